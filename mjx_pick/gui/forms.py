"""The GUI's form fields and their validation, apart from any web framework.

Each field names the settings dataclass field it sets (``section.field``). Values are
checked by the dataclasses themselves (their ``__post_init__`` range checks), one field
at a time so that every bad field gets its own message, then together (cross-field
rules such as "two fingers must fit the stroke"). A :class:`ConfigError` is mapped back
to the field it names; the page shows it next to that field.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import tomllib
from pathlib import Path

from mjx_pick.core.config import ConfigError, describe_fields, to_toml, write_atomic
from mjx_pick.core.gripper import GripperSpec, gripper_from_data
from mjx_pick.core.physics import ContactParams
from mjx_pick.core.pickpoints import PickConfig
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import registry
from mjx_pick.gui.formatting import key_words, outcome_words, page_text
from mjx_pick.kernels.types import FAILURES

SECTIONS = {
    "gripper": GripperSpec,
    "picks": PickConfig,
    "grasp": GraspConfig,
    "contact": ContactParams,
}


@dataclasses.dataclass(frozen=True)
class Field:
    """One number on a form: the dataclass field it sets, its label and the step of its
    arrows; its unit, meaning and range are the field's declaration (``config.setting``)."""

    key: str  # section.field
    label: str
    step: float = 1.0

    @property
    def section(self) -> str:
        return self.key.split(".", 1)[0]

    @property
    def name(self) -> str:
        return self.key.split(".", 1)[1]

    @property
    def declared(self) -> dict:
        """The field's declaration: unit, meaning, default, range."""
        return next(f for f in describe_fields(SECTIONS[self.section]) if f["name"] == self.name)

    @property
    def unit(self) -> str:
        """Its unit ("" for a plain number)."""
        unit = self.declared["unit"]
        return "" if unit in (None, "-") else unit

    @property
    def hint(self) -> str:
        """What it means and the range it must lie in, in a line."""
        return f"{self.declared['meaning']} ({self.declared['range']})"


# the paper's "Set gripper parameters" tab (Fig. 10), in its order
GRIPPER_FIELDS = (
    Field("gripper.stroke_mm", "stroke width"),
    Field("gripper.finger_width_mm", "finger width"),
    Field("gripper.finger_depth_mm", "finger depth"),
    Field("gripper.pad_height_mm", "pad height"),
    Field("gripper.force_min_n", "smallest force"),
    Field("gripper.force_max_n", "largest force"),
    Field("gripper.speed_min_mm_s", "slowest closing"),
    Field("gripper.speed_max_mm_s", "fastest closing"),
)
PICK_FIELDS = (
    Field("picks.safety_zone_mm", "safety zone", 0.5),
    Field("picks.min_coverage", "minimum coverage", 0.05),
)
PROCEDURE_FIELDS = (
    Field("grasp.grip_force_n", "grip force F_d"),
    Field("grasp.kp_mm_s_per_n", "P gain", 0.1),
    Field("grasp.closing_speed_mm_s", "closing speed"),
    Field("grasp.safety_factor", "safety margin S_f", 0.05),
    Field("grasp.lift_height_mm", "lift height"),
    Field("grasp.hold_s", "hold", 0.05),
)
CONTACT_FIELDS = (
    Field("contact.pad_friction", "pad friction", 0.01),
    Field("contact.table_friction", "table friction", 0.01),
)
SETTINGS_FIELDS = GRIPPER_FIELDS + PICK_FIELDS + PROCEDURE_FIELDS + CONTACT_FIELDS

_NAMED = re.compile(r"^(?:gripper\[[^\]]*\]|grasp|picks|contact)\.(\w+)")


@dataclasses.dataclass(frozen=True)
class Settings:
    """Everything the gripper tab sets: the four dataclasses of the CLI's flags."""

    gripper: GripperSpec
    picks: PickConfig
    grasp: GraspConfig
    contact: ContactParams


def defaults(gripper: GripperSpec, **others) -> dict[str, float]:
    """Field values for a gripper with the paper's other settings (or those given as
    picks=, grasp=, contact=: a run's)."""
    objs = {
        "gripper": gripper,
        "picks": others.get("picks") or PickConfig(),
        "grasp": others.get("grasp") or GraspConfig(),
        "contact": others.get("contact") or ContactParams(),
    }
    return {f.key: float(getattr(objs[f.section], f.name)) for f in SETTINGS_FIELDS}


# a settings key in a library's message: section.field (gripper[name].field), or a form
# field's bare name
_INTERNAL = re.compile(
    r"\b(gripper\[[^\]]*\]|gripper|grasp|picks|contact|solver)\.(\w+)|\b("
    + "|".join(f.name for f in SETTINGS_FIELDS)
    + r")\b"
)


# a gripper as a library's message names it, "gripper[robotiq-2f85]"
_GRIPPER = re.compile(r"\bgripper\[([^\]]*)\]")


def setting_words(section: str, name: str) -> str:
    """A setting in the page's words: a form field's label and unit, else its section,
    meaning and unit (``sweep_labels``), else the key in words."""
    key = f"{section.split('[', 1)[0]}.{name}"
    form = next((f for f in SETTINGS_FIELDS if f.key == key), None)
    if form is not None:
        return f"{form.label} ({form.unit})" if form.unit else form.label
    return sweep_labels().get(key) or key_words(key)


def user_words(message: str) -> str:
    """A settings error in the form's words: each internal field name (``contact.pad_friction``,
    ``gripper[robotiq-2f85].stroke_mm``, ``stroke_mm``) becomes its label and unit --
    the library's own text is not added: its keys are the program's words."""
    labels = {f.name: f"{f.label} ({f.unit})" if f.unit else f.label for f in SETTINGS_FIELDS}

    def label(m: re.Match) -> str:
        if m.group(3):
            return labels[m.group(3)]
        return setting_words(m.group(1), m.group(2))

    words = _INTERNAL.sub(label, page_text(message))
    return _GRIPPER.sub(r"gripper \1", words)  # gripper[robotiq-2f85]: the program's


# the CLI's flags as the page names the control that sets them (a CLI message may name
# one; the page has no flags). Flags the page has no control for are said as the CLI's
# option in words, never as a flag.
FLAG_WORDS = {
    "--n": "pick-points (tab 3)",
    "--seed": "seed (tab 3)",
    "--traces": "traced best and worst (tab 3)",
    "--chunk-size": "pick-points per saved chunk (tab 3)",
    "--out": "run folder name",
    "--resume": "'resume' ticked (tab 3)",
    "--step-check": "'check each label' (tab 3)",
    "--stability-um": "'check each label' (tab 3)",
    "--backend": "backend (tab 2)",
    "--gripper-file": "gripper (tab 2)",
    "--grasp": "procedure settings (tab 2)",
    "--contact": "contact settings (tab 2)",
    "--safety-zone-mm": "safety zone (mm) (tab 2)",
    "--min-coverage": "minimum coverage (tab 2)",
    "--mass-g": "mass (g) (tab 1)",
    "--px-per-mm": "image scale (px per mm) (tab 1)",
    "--thickness-mm": "thickness (mm) (tab 1)",
    "--unit": "mesh unit (tab 1)",
    "--largest-body": "'largest body only' ticked (tab 1)",
    "--top-k": "top pick-points (Studies)",
    "--m": "perturbed draws each (Studies)",
    "--steps": "optimiser steps (Studies)",
    "--params": "parameters to fit (Studies)",
    "--grippers": "presets (Studies)",
    "--param": "parameter (Parameter sweep)",
    "--results": "the run open in tab 4 (its folder)",
    "--grasps": "grasps from (tab 3)",
    "--depth-mm": "grasp depth (mm) (tab 3)",
}
# a flag in brackets after the words it stands for ("check mass_g (--mass-g)"): the
# words are said already
_FLAG_AFTER = re.compile(r" \((?:--[a-z][a-z0-9-]*(?: or |, )?)+\)")
_FLAG = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)(?: \(\w+=\w+\))?")
# a recorded run's settings that changed (rundir.what_changed): "changed: a: 1 -> 2; ..."
_CHANGED = re.compile(r"(changed: )(.*?)(?=\.(?: |$)|$)")
_CHANGED_KEY = re.compile(r"(^|; )([\w.\[\]-]+)(: )")
_PROGRAM = (  # the CLI's names of its own runs, as the page says them
    (
        re.compile(r"holds `mjx-pick (\w+)` results of another configuration"),
        r"holds the results of {} run with other settings",
    ),
    (re.compile(r"`mjx-pick (\w+)`"), r"{} run"),
)
# "--results runs/do is of object ...": the run a study reads, by its folder
_RESULTS = re.compile(r"--results (\S+)")
# an install command in a message (the CLI's advice to its user): the page's user may not
# be who installs the software
_PIP = re.compile(r"""pip install (?:"[^"]*"|'[^']*'|\S+)(?: \([^)]*\))?""")


def _install_words(m: re.Match) -> str:
    extra = re.search(r"\[(\w+)\]", m.group(0))
    what = f"mjx-pick's {extra.group(1)} extra" if extra else "the software it names"
    return f"{what}, installed on this machine by whoever installs its software"


# an outcome's label (the results' failure column: force_not_reached), also in quotes
_OUTCOME = re.compile(r"\b(?:" + "|".join(o for o in FAILURES if "_" in o) + r")\b")


# a program's key left in a message (a recorded field, a library's argument): a
# lower-case name with underscores that ends in a unit or is one of key_words' own --
# never a file's name (a dot, a slash or a quote beside it) or other user text
_KEY = re.compile(r"(?<![\w./'\"`-])([a-z][a-z0-9]*(?:_[a-z0-9]+)+)(?![\w/'\"`-]|\.\w)")


def page_words(message: str) -> str:
    """Any message for the page -- a library's, the CLI's, a check's -- in the page's
    words: no path of the software's files (``page_text``), the CLI's advice as the
    page's controls (``page_advice``), each setting and recorded key by its label or in
    words (``user_words``, ``key_words``), each CLI flag by the control that sets it."""
    text = user_words(page_advice(_RESULTS.sub(r"the run \1", _FLAG_AFTER.sub("", message))))

    def changed(m: re.Match) -> str:
        keys = _CHANGED_KEY.sub(
            lambda k: k.group(1) + _recorded_words(k.group(2)) + k.group(3), m.group(2)
        )
        return m.group(1) + keys

    text = _CHANGED.sub(changed, text)
    for pattern, words in _PROGRAM:
        text = pattern.sub(lambda m, w=words: w.format(_article(m.group(1))), text)
    text = _KEY.sub(lambda m: key_words(m.group(1)) if _is_key(m.group(1)) else m.group(1), text)
    text = _PIP.sub(_install_words, text)
    text = _OUTCOME.sub(lambda m: outcome_words(m.group(0)), text)
    return _flag_words(text)


def file_words(message: str) -> str:
    """A message about what is wrong inside a file the user wrote (a gripper TOML, a
    grasp file, a TRIALS.csv) in the page's words, its keys and columns kept -- they
    are the user's own words there (``column depth_mm``, ``stroke_mm = -5``): no path
    of the software's files, the CLI's advice and flags as the page's controls (a CLI
    flag is never a file's word)."""
    return _flag_words(page_advice(_FLAG_AFTER.sub("", page_text(message))))


def _flag_words(text: str) -> str:
    """Every CLI flag in text as the page's control (``FLAG_WORDS``, else its key's words)."""
    return _FLAG.sub(
        lambda m: FLAG_WORDS.get(m.group(1), key_words(m.group(1)[2:].replace("-", "_"))), text
    )


def _article(word: str) -> str:
    return ("an " if word[:1] in "aeiou" else "a ") + word


def _is_key(name: str) -> bool:
    """Whether a name with underscores is a program's key (its unit in its name, or a
    key with words of its own), not a word a user chose."""
    return key_words(name) != name.replace("_", " ")


def _recorded_words(key: str) -> str:
    """A key of a run's recorded settings (rundir's manifest) in words."""
    section, _, name = key.partition(".")
    if name and section.split("[", 1)[0] in (*SECTIONS, "solver"):
        return setting_words(section, name)
    return key_words(key)


def field_of(message: str, section: str) -> str | None:
    """The form key a ConfigError message names (``grasp.grip_force_n = ...``), if any."""
    m = _NAMED.match(message)
    if m is None:
        return None
    key = f"{section}.{m.group(1)}"
    return key if any(f.key == key for f in SETTINGS_FIELDS) else None


def build(
    values: dict[str, float | None],
    gripper: GripperSpec,
    contact: ContactParams | None = None,
    grasp: GraspConfig | None = None,
    picks: PickConfig | None = None,
) -> tuple[Settings | None, dict]:
    """Settings from form values, or None and {key: message} for every bad field.

    Args:
      values: {section.field: number or None (left empty)}.
      gripper: the gripper the form started from (name, masses, drive: the fields the
        form does not show).
      contact: the contact parameters it started from (e.g. calibrated ones; default:
        the paper's), for the fields the form does not show (stiffness, damping, ...).
      grasp, picks: the procedure and pick-point settings it started from (a run's,
        loaded from its folder; default: the paper's), likewise.
    Returns:
      (settings, {}) or (None, errors); errors may hold "" for a message that names no
      field (shown above the form).
    """
    errors: dict[str, str] = {}
    base = {"gripper": gripper, "picks": picks or PickConfig(), "grasp": grasp or GraspConfig()}
    base["contact"] = contact or ContactParams()
    changes: dict[str, dict] = {s: {} for s in SECTIONS}
    for f in SETTINGS_FIELDS:
        value = values.get(f.key)
        if value is None or value == "":
            errors[f.key] = f"{f.label} is required"
            continue
        try:
            value = float(value)
        except (TypeError, ValueError):
            errors[f.key] = f"{f.label}: {value!r} is not a number"
            continue
        try:  # alone on the defaults: the field's own range
            dataclasses.replace(base[f.section], **{f.name: value})
        except ConfigError as err:
            errors[f.key] = user_words(str(err))
            continue
        changes[f.section][f.name] = value
    if errors:
        return None, errors
    built = {}
    for section, obj in base.items():
        try:
            built[section] = dataclasses.replace(obj, **changes[section])
        except ConfigError as err:  # cross-field rules
            key = field_of(str(err), section) or _cross_field(section, str(err))
            errors[key] = user_words(str(err))
    if errors:
        return None, errors
    if built["gripper"] != gripper and built["gripper"].name == gripper.name:
        # an edited preset is another gripper: results must not carry the preset's name
        built["gripper"] = dataclasses.replace(built["gripper"], name=f"{gripper.name}-edited")
    try:
        built["grasp"].check_gripper(built["gripper"])
    except ConfigError as err:
        errors[field_of(str(err), "grasp") or ""] = user_words(str(err))
        return None, errors
    return Settings(**built), {}


def _cross_field(section: str, message: str) -> str:
    if section == "gripper" and "fingers cannot fit the stroke" in message:
        return "gripper.finger_depth_mm"
    return ""


def gripper_from_toml(text: str, where: str = "gripper TOML") -> GripperSpec:
    """A GripperSpec from TOML text; ConfigError names the line or the field."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{where} is not valid TOML: {err}") from err
    if not data:
        raise ConfigError(f"{where} is empty: give every gripper field, or base and name")
    return gripper_from_data(data, where, Path.cwd())


def write_inputs(settings: Settings, folder: Path, workdir: Path | None = None) -> dict[str, Path]:
    """The settings as the TOML files the CLI reads (--gripper-file, --grasp, --contact).

    Files that a run already reads are never replaced: when folder holds other
    settings, they go to folder-2, folder-3, ... -- as when one of them is a link (it
    is never read or written through: it may lead outside the work folder), or the
    folder itself leads outside workdir (default: folder's parent's parent, the work
    folder of ``WORKDIR/inputs/<run>``).
    """
    from mjx_pick.gui.workfolder import inside

    workdir = Path(folder).parent.parent if workdir is None else workdir
    texts = {name: to_toml(getattr(settings, name)) for name in ("gripper", "grasp", "contact")}
    for k in range(1, 1000):
        where = folder if k == 1 else folder.with_name(f"{folder.name}-{k}")
        paths = {name: where / f"{name}.toml" for name in texts}
        if inside(where, workdir) is None or any(p.is_symlink() for p in paths.values()):
            continue
        if all(not p.exists() or p.read_text() == texts[n] for n, p in paths.items()):
            for name, path in paths.items():
                if not path.exists():
                    write_atomic(path, texts[name])
            return paths
    raise ConfigError(f"{folder}: too many different settings for one run name")


def cli_flags(settings: Settings, paths: dict[str, Path]) -> list[str]:
    """The CLI flags that give `mjx-pick evaluate/sweep` these settings."""
    return [
        "--gripper-file",
        str(paths["gripper"]),
        "--grasp",
        str(paths["grasp"]),
        "--contact",
        str(paths["contact"]),
        "--safety-zone-mm",
        repr(float(settings.picks.safety_zone_mm)),
        "--min-coverage",
        repr(float(settings.picks.min_coverage)),
    ]


# the sections of a sweep's parameters, in the page's words
_SWEPT_SECTIONS = {
    "gripper": "gripper",
    "grasp": "procedure",
    "contact": "contact",
    "solver": "solver",
}


@functools.cache
def sweep_labels() -> dict[str, str]:
    """Every parameter a sweep takes, {key: what the page calls it}: a form field's own
    label and unit, else its section, meaning (the declaration's, without its remark in
    brackets) and unit -- never the key (``contact.pad_friction``). Aliases are left out: each
    parameter once."""
    from mjx_pick.studies.sweeps import describe_params

    form = {f.key: f"{f.label} ({f.unit})" if f.unit else f.label for f in SETTINGS_FIELDS}
    labels = {}
    for row in describe_params():
        key = row["name"]
        if not row["sweepable"]:
            continue
        if key in form:
            labels[key] = form[key]
            continue
        meaning, unit = row["meaning"].split(" (", 1)[0], row["unit"]
        said = unit in (None, "-") or meaning.endswith(f" {unit}")  # "... iterations"
        unit = "" if said else f" ({unit})"
        labels[key] = f"{_SWEPT_SECTIONS[key.split('.', 1)[0]]}: {meaning}{unit}"
    return labels


def sweep_range(name: str) -> tuple[float, float, float]:
    """A parameter's starting sweep (start, end, step): five values around its default
    within its declared range, so that choosing another parameter never keeps the
    previous one's numbers (a friction's 0.4-1.0 as a finger width in mm)."""
    from mjx_pick.core.config import field_number
    from mjx_pick.studies.sweeps import SECTIONS as SWEPT
    from mjx_pick.studies.sweeps import canonical, describe_params

    key = canonical(name)
    info = next(r for r in describe_params(key) if r["name"] == key)
    section, field = key.split(".", 1)
    rule = field_number(SWEPT[section], field)
    default = info["default"]
    if default is None:  # a field whose default is "none": the middle of its range
        default = ((rule.lo or 0.0) + (rule.hi if rule.hi is not None else 1.0)) / 2
    default = float(default)
    lo = default * 0.5 if default > 0 else default - 1.0
    hi = default * 1.5 if default > 0 else default + 1.0
    if rule.lo is not None:
        lo = max(lo, rule.lo)
    if rule.hi is not None:
        hi = min(hi, rule.hi)
    if not hi > lo:  # a default on the edge of its range
        return default, default, 1.0
    step = float(f"{(hi - lo) / 4:.2g}") or 1.0
    start = round(round(lo / step) * step, 10)
    if rule.lo is not None and start < rule.lo:
        start = round(start + step, 10)
    return start, round(start + 4 * step, 10), step


def sweep_values(start, end, step) -> tuple[tuple[float, ...] | None, dict]:
    """The paper's sweep tab (start, end, step) as values, or errors by field."""
    errors = {}
    for key, v in (("start", start), ("end", end), ("step", step)):
        if v is None or v == "":
            errors[key] = f"{key} is required"
    if errors:
        return None, errors
    start, end, step = float(start), float(end), float(step)
    if step <= 0:
        return None, {"step": f"step = {step:g} must be > 0"}
    if end < start:
        return None, {"end": f"end = {end:g} must be >= start = {start:g}"}
    count = (end - start) / step
    if abs(count - round(count)) > 1e-6 * max(1.0, count):
        return None, {"step": f"step = {step:g} does not divide end - start = {end - start:g}"}
    n = int(round(count)) + 1
    if n > 50:
        return None, {"step": f"{n} values: at most 50 per sweep here (use the CLI for more)"}
    return tuple(round(start + i * step, 12) for i in range(n)), {}


def sweep_problem(settings: Settings, name: str, values) -> str:
    """Why a sweep of parameter name over values cannot run with these settings ('' if
    it can): each value is checked as the sweep will set it (the parameter's range, the
    rules between fields and against the gripper), before anything starts."""
    from mjx_pick.core.settings import Settings as RunSettings
    from mjx_pick.studies.sweeps import apply, canonical

    try:
        key = canonical(name)
    except ConfigError as err:
        return str(err)
    form = next((f.label for f in SETTINGS_FIELDS if f.key == key), None)
    label = form or sweep_labels().get(key, key)
    base = RunSettings(gripper=settings.gripper, contact=settings.contact, grasp=settings.grasp)
    for value in values:
        try:
            varied = apply(base, key, value)
            varied.grasp.check_gripper(varied.gripper)
        except ConfigError as err:
            return f"{label} = {value:g} cannot be simulated: {user_words(str(err))}"
    return ""


def backend_choices() -> list[str]:
    """The backend select's options: 'auto' and every backend of the registry that
    labels pick-points at the page's settings and can run on this machine
    (:func:`backend_problems`). The differentiable backend is left out: it runs one
    fixed physics, for derivatives, which the page never computes."""
    return [
        c
        for c in registry.choices()
        if c != registry.differentiable() and c not in backend_problems()
    ]


@functools.cache
def backend_problems() -> dict[str, str]:
    """{backend: why it cannot run on this machine} for each backend of the registry
    that cannot (a choice that would fail seconds after its start is not offered).
    Asked without starting a GPU runtime in the server (JAX's would take most of a
    GPU's memory, Warp's a context): a backend that needs an NVIDIA GPU is left out
    where no NVIDIA driver is loaded; any other by the registry's own check."""
    from mjx_pick.engine.devices import nvidia_driver_present

    driver = nvidia_driver_present()
    problems = {}
    for name, e in registry.ENTRIES.items():
        if e.device is registry.Device.NVIDIA_GPU:
            if not driver:
                problems[name] = "no NVIDIA GPU on this machine"
        elif e.problem is not None and e.jax is not registry.Jax.DEVICES:
            why = registry.problem(e)
            if why:
                problems[name] = why
    return problems


def backend_note() -> str:
    """What the page says of the backends it does not offer here, and why ('' if none)."""
    left = {k: v for k, v in backend_problems().items() if k != registry.differentiable()}
    if not left:
        return ""
    return "not on this machine: " + "; ".join(f"{k} ({why})" for k, why in left.items())


# the CLI's advice in a refusal, as the page offers it (it has no flags, and never
# deletes a run: a run's name is its folder)
_PAGE_ADVICE = (
    (
        "Keep them: continue it with its settings and --resume, or write elsewhere with "
        "--out NEW; --overwrite deletes them",
        "Keep them: continue it with its own settings ('Load this run folder's settings' "
        "in tab 3, then Start), or choose another run folder name",
    ),
    (
        "Keep them: write elsewhere with --out NEW; --overwrite deletes them",
        "Keep them: choose another run folder name",
    ),
    (
        "keep them and write elsewhere with --out NEW, or pass --overwrite to delete them "
        "and start again",
        "keep them: choose another run folder name",
    ),
    (
        "Keep them and write elsewhere with --out NEW, or pass --overwrite to delete them "
        "and start again",
        "Keep them: choose another run folder name",
    ),
    (
        "pass --resume to continue it, or choose another --out",
        "tick 'resume' to continue it, or choose another run folder name",
    ),
    (
        "give the object (and --mass-g ...) it was made with",
        "import the object it was made with in tab 1 (its file or shipped object, scale, "
        "thickness and mass)",
    ),
    # a run estimated longer than a few minutes (studies.duration.refuse_long): the page
    # asks before it starts, and passes --yes once the user confirms
    ("pass --yes to start it, or make it smaller", "start it anyway, or make it smaller"),
    ("choose another --out or pass --overwrite", "choose another run folder name"),
    ("leave out --resume to start one there", "untick 'resume' to start one there"),
    ("choose another --out", "choose another run folder name"),
    ("--out NEW", "another run folder name"),
)


def page_advice(message: str) -> str:
    """A refusal's advice in the page's words (run folder names and the resume box,
    not --out, --resume and --overwrite)."""
    for cli, page in _PAGE_ADVICE:
        message = message.replace(cli, page)
    if message.startswith("--out "):  # the folder a refusal names first
        message = "run folder " + message.removeprefix("--out ")
    if message.startswith("--resume: "):  # resume asked for where nothing can resume
        message = "'resume' is ticked, but run folder " + message.removeprefix("--resume: ")
    return message
