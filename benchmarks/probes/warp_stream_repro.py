"""Reproduce, in a process of its own, the Warp "unknown stream" failure of a program that
carries model fields, and check its remedy (--remedy):

  unfixed   without engine.warp_backend.keep_xla_stream_registrations: a wp.Stream
            wrapper of XLA's stream, freed by Python's cyclic garbage collector while a
            newer wrapper of the same stream begins a graph capture, unregisters the
            stream under it (Warp's registry keeps no count)
  shipped   as mjx_pick runs it (streams Warp does not own stay registered)
  gc_off    unfixed, with the cyclic garbage collector off for the run

On a GPU machine, run it at least twice (the first process on a machine builds Warp's
kernels and did not fail):

  python benchmarks/probes/warp_stream_repro.py --remedy unfixed -- sweep door_opener \\
      --param gripper.finger_width_mm=12,22,30 --n 64 --backend warp --out DIR
"""

import argparse
import gc
import sys
import traceback


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--remedy", choices=("unfixed", "shipped", "gc_off"), default="shipped")
    p.add_argument("cli", nargs=argparse.REMAINDER)
    a = p.parse_args()
    from mjx_pick.engine import warp_backend

    if a.remedy in ("unfixed", "gc_off"):
        warp_backend.keep_xla_stream_registrations = lambda: None
    if a.remedy == "gc_off":
        gc.disable()
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
