"""Reproduce, in a process of its own, the Warp "unknown stream" failure of a program that
carries model fields, with one candidate remedy applied (--remedy):

  none          as shipped, with carried model fields switched on
  keep_streams  Warp's external-stream wrappers never unregister the stream they wrap
                (wp.Stream.__del__ of a non-owning wrapper unregisters the raw stream even
                while a newer wrapper of the same stream is about to capture on it)
  gc_off        Python's cyclic garbage collector off for the run

  python benchmarks/warp_stream_repro.py --remedy none --out DIR -- sweep door_opener ...
"""

import argparse
import gc
import sys
import traceback


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--remedy", choices=("none", "keep_streams", "gc_off"), default="none")
    p.add_argument("--no-carry", action="store_true")
    p.add_argument("cli", nargs=argparse.REMAINDER)
    a = p.parse_args()
    from mjx_pick.engine import variants

    variants.WARP_CARRIES_MODEL_FIELDS = not a.no_carry
    if a.remedy == "gc_off":
        gc.disable()
    if a.remedy == "keep_streams":
        import warp._src.context as wpc

        orig_del = wpc.Stream.__del__

        def _del(self):
            if getattr(self, "owner", True):
                orig_del(self)

        wpc.Stream.__del__ = _del
    from mjx_pick.cli import main as cli

    argv = a.cli[1:] if a.cli[:1] == ["--"] else a.cli
    try:
        rc = cli(argv)
    except Exception:
        traceback.print_exc()
        rc = 99
    print(f"REMEDY {a.remedy} RC {rc}", flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
