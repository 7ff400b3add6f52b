"""User text written into another format: ONE escape function per target format.

A name, a path or a label a user gives may hold any character the name rule
(``config.check_name``) lets through -- a quote, '<', '&', an emoji. Wherever such text
is written into a file of another format it goes through the function of that format,
and nowhere else is it quoted by hand:

- :func:`xml_attr`: an XML attribute's value (the scene's MJCF, ``scene.xml``);
- :func:`toml_string`: a TOML basic string (``best_gripper.toml``, ``contact.toml``);
- :func:`html_text`: HTML text or an attribute's value (``report.html``);
- :func:`shell_word`: one word of a POSIX shell line (the commands the CLI prints).

Each returns text that reads back as exactly the text given (a test round-trips every
one through its format's own parser).
"""

from __future__ import annotations

import html
import shlex

__all__ = ["html_text", "shell_word", "toml_string", "xml_attr"]

# XML 1.0 cannot hold these at all, escaped or not (only tab, newline and carriage
# return of the C0 controls are characters of XML); they are written as U+FFFD
_XML_FORBIDDEN = {c for c in range(32) if c not in (9, 10, 13)} | set(range(0xD800, 0xE000))
_XML_FORBIDDEN |= {0xFFFE, 0xFFFF}
_XML_ENTITIES = {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&apos;"}


def xml_attr(text: object) -> str:
    """text as the value of an XML attribute (written between double quotes): markup
    characters as entities; tab, newline and carriage return as character references
    (a parser would turn them into spaces otherwise); characters XML 1.0 cannot hold
    (other control characters, lone surrogates) as U+FFFD."""

    def one(c: str) -> str:
        o = ord(c)
        if o in _XML_FORBIDDEN:
            return "\ufffd"
        if o in (9, 10, 13):
            return f"&#{o};"
        return _XML_ENTITIES.get(c, c)

    return "".join(one(c) for c in str(text))


def toml_string(text: object) -> str:
    """text as a TOML basic string, quotes included: any Unicode as it is (json.dumps
    would write an emoji as two surrogate escapes, which TOML refuses); quote,
    backslash and control characters escaped."""

    def one(c: str) -> str:
        if c in '"\\':
            return "\\" + c
        if ord(c) < 32 or ord(c) == 127:
            return f"\\u{ord(c):04x}"
        return c

    return '"' + "".join(one(c) for c in str(text)) + '"'


def html_text(text: object) -> str:
    """text as HTML: element content or an attribute's value (quotes escaped too)."""
    return html.escape(str(text), quote=True)


def shell_word(text: object) -> str:
    """text as one word of a POSIX shell line, quoted only where it must be (a path
    with a space, a quote or '$' pasted into a terminal stays one argument)."""
    return shlex.quote(str(text))
