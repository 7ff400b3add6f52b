"""The ``mjx-pick`` argument parser: every subcommand, its options and their help."""

from __future__ import annotations

import argparse

from mjx_pick.cli.commands import (
    cmd_assets,
    cmd_cache_clear,
    cmd_cache_info,
    cmd_calibrate,
    cmd_compare,
    cmd_design,
    cmd_evaluate,
    cmd_export,
    cmd_gui,
    cmd_params,
    cmd_picks,
    cmd_presets,
    cmd_report,
    cmd_robust,
    cmd_sweep,
    cmd_trials_agree,
    cmd_trials_fit,
    cmd_trials_plan,
    cmd_trials_record,
    cmd_validate,
    cmd_view,
)
from mjx_pick.cli.inputs import raise_problems
from mjx_pick.cli.setting_flags import PHYSICS_FLAGS, PICK_FLAGS, add_setting_flags
from mjx_pick.core.config import ConfigError
from mjx_pick.core.numbers import INPUTS, REPAIR_DEFAULTS
from mjx_pick.engine import registry


class Refused(str):
    """A flag's text that its rule refused; ``problem`` says why (see :func:`refused`)."""

    problem: str


def number(name: str, flag: str):
    """An argparse type: the flag's text parsed and checked by the rule of the input
    `name` (``core.numbers.INPUTS``): finite, in range, whole where it counts. A value
    it refuses comes back as :class:`Refused`, so that :func:`refused` reports every
    bad number of a command line at once. (A settings field's flag is checked by its
    dataclass, with the field's own declaration, with the other settings.)"""
    rule = INPUTS[name]

    def parse(text: str):
        try:
            return rule.parse(flag, text)
        except ConfigError as err:
            bad = Refused(text)
            bad.problem = f"{err}"
            return bad

    parse.__name__ = name  # argparse names the type in some of its messages
    return parse


def path_of(flag: str):
    """An argparse type for a path flag (--out): its text, or :class:`Refused` where it
    is empty -- an unset variable in ``--out "$DIR"`` would otherwise write into the
    current folder."""

    def parse(text: str):
        if text.strip():
            return text
        bad = Refused(text)
        bad.problem = (
            f"{flag} {text!r}: empty; give a folder or file (an unset variable? the current "
            "folder is --out .)"
        )
        return bad

    parse.__name__ = "path"
    return parse


def refused(args: argparse.Namespace) -> None:
    """Raise one ConfigError naming every number of the command line that its rule
    refused (nothing when none was)."""
    raise_problems([v.problem for v in vars(args).values() if isinstance(v, Refused)])


class DefaultsHelp(argparse.HelpFormatter):
    """Help that shows each option's default: "(default: X)" is appended where the
    option has one (not for None, a bare switch, or help that already names it)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = str(action.help or "")  # a setting flag's help is made when first read
        if "%(default)" in text or "(default" in text:
            return text
        default = action.default
        if default is None or default is argparse.SUPPRESS or isinstance(default, bool):
            return text
        if action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE):
            return text + " (default: %(default)s)"
        return text


class Parser(argparse.ArgumentParser):
    """The root parser and every subcommand's: defaults shown in --help."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", DefaultsHelp)
        super().__init__(*args, **kwargs)


def _add_object_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    """The object a command loads (``core.objects.load_object``) and how (required:
    False where a file names it, as calibrate's TRIALS.csv does)."""
    g = p.add_argument_group("object")
    g.add_argument(
        "object",
        nargs=None if required else "?",
        help="a shipped asset name (mjx-pick assets), a top-down image (PNG/JPG) or a mesh "
        "(STL/OBJ/PLY/GLB)" + ("" if required else "; none with a TRIALS.csv, which names it"),
    )
    _add_object_size_args(g)
    _add_mesh_args(g)
    g.add_argument(
        "--pick-height-mm",
        type=number("pick_height_mm", "--pick-height-mm"),
        help="fingertip height above the table at the grasp, mm (default: --grasp-height's rule)",
    )
    g.add_argument(
        "--simplify-mm",
        type=number("simplify_mm", "--simplify-mm"),
        help="outline simplification tolerance of an image, mm (default: 0.3)",
    )
    g.add_argument(
        "--material",
        help="object material name, recorded with the results (default: pla; an asset: its own)",
    )
    g.add_argument(
        "--no-cache",
        action="store_true",
        help="neither read nor write the cache of object preparation and compiled programs "
        "(mjx-pick cache info; the same as MJX_PICK_CACHE=0)",
    )


def _add_object_size_args(g) -> None:
    """An image's scale and thickness; an object's mass or density."""
    g.add_argument(
        "--px-per-mm",
        type=number("px_per_mm", "--px-per-mm"),
        help="image scale, pixels per mm (an image: required; a shipped asset: its own)",
    )
    g.add_argument(
        "--thickness-mm",
        type=number("thickness_mm", "--thickness-mm"),
        help="object thickness (prism height), mm (an image: required; an asset: its own)",
    )
    g.add_argument(
        "--mass-g",
        type=number("mass_g", "--mass-g"),
        help="object mass, g (an image or mesh: this or --density-kg-m3; an asset: its own)",
    )
    g.add_argument(
        "--density-kg-m3",
        type=number("density_kg_m3", "--density-kg-m3"),
        help="object density, kg/m^3, instead of --mass-g",
    )


def _add_mesh_args(g) -> None:
    """What only a mesh takes: its unit, resting pose and disconnected bodies."""
    g.add_argument(
        "--unit", choices=("m", "mm"), help="unit of a mesh file's coordinates (a mesh: required)"
    )
    g.add_argument(
        "--pose",
        choices=("as_given", "stable"),
        default="as_given",
        help="a mesh's resting pose: as in the file, or its most stable resting pose",
    )
    g.add_argument(
        "--largest-body",
        action="store_true",
        help="a mesh of several disconnected bodies: keep the largest (default: refuse it)",
    )
    for name, what in (
        ("repair_volume_pct", "volume in doubt, %%"),
        ("repair_com_mm", "centre-of-mass change, mm"),
        ("repair_bounds_mm", "bounding-box change, mm"),
    ):
        flag = "--" + name.replace("_", "-")
        g.add_argument(
            flag,
            type=number(name, flag),
            help=f"a mesh that is not a closed solid is repaired within this {what} "
            f"(default: {REPAIR_DEFAULTS[name]:g})",
        )


def _add_gripper_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("gripper")
    g.add_argument(
        "--gripper",
        help="preset name (mjx-pick presets) (default: robotiq-2f85; robust --results: the run's)",
    )
    g.add_argument(
        "--gripper-file", help="a gripper TOML file (GripperSpec fields; overrides --gripper)"
    )


def _add_physics_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("physics (mjx-pick params: every setting, its unit and range)")
    g.add_argument(
        "--contact",
        help="contact parameters TOML (ContactParams fields, or calibrate's contact.toml; "
        "default: the paper's Table 1)",
    )
    g.add_argument(
        "--solver", help="solver settings TOML (SolverParams fields; default: mjx-pick params)"
    )
    g.add_argument(
        "--grasp", help="grasp procedure TOML (GraspConfig fields; default: mjx-pick params)"
    )
    add_setting_flags(g, PHYSICS_FLAGS)
    g.add_argument(
        "--backend",
        choices=registry.choices(),
        default=registry.AUTO,
        help=registry.backend_help(),
    )
    g.add_argument(
        "--batch-size",
        type=number("batch_size", "--batch-size"),
        help=f"simulations per backend call (default: {registry.batch_size_help()})",
    )


def _add_pick_args(p: argparse.ArgumentParser, n_help: str | None = None) -> None:
    """The pick-point options; n_help: --n's help where it has no default of its own
    (evaluate: its default depends on --picks)."""
    g = p.add_argument_group("pick-points")
    g.add_argument(
        "--n",
        type=number("n", "--n"),
        default=None if n_help else 1000,
        help=n_help or "pick-points to generate (Normal mode)",
    )
    g.add_argument(
        "--seed", type=number("seed", "--seed"), default=0, help="seed: same seed, same pick-points"
    )
    add_setting_flags(g, PICK_FLAGS)


def _add_progress(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (on stderr; without a terminal: a line at the first work done, "
        "then every 10 percent and at least every minute)",
    )


def _add_yes(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--yes",
        action="store_true",
        help="start a run estimated to take longer than a few minutes on this machine "
        "(without it, such a run is refused, saying how long it would take)",
    )


def _add_ray(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--ray",
        metavar="auto|ADDRESS",
        help="simulate on a Ray cluster: auto, or its head's HOST:PORT (pip install "
        "'mjx-pick[cluster]'; docs/cluster.md); this process still writes --out "
        "(default: this machine)",
    )


def _add_resume(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run of the same command and settings in --out "
        "from its finished chunks",
    )


def _add_overwrite(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace what another command (or another configuration) wrote in --out",
    )


def _version_line() -> str:
    """mjx-pick's version and the physics engines it runs on (rundir.versions)."""
    from mjx_pick.outputs.rundir import versions

    v = {k: x or "not installed" for k, x in versions().items()}
    engines = ("mujoco", "mujoco-warp", "warp-lang", "mujoco-mjx", "jax")
    parts = ", ".join(f"{d} {v[d]}" for d in engines)
    return f"mjx-pick {v['mjx-pick']} ({parts})"


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(
        prog="mjx-pick",
        description="mjx-pick: evaluate robot pick-points by physics simulation (MuJoCo).",
    )
    ap.add_argument(
        "--version",
        action="version",
        version=_version_line(),
        help="show mjx-pick's version and its physics engines' and exit",
    )
    sub = ap.add_subparsers(dest="command", required=True, parser_class=Parser)
    # one function per subcommand, in the order `mjx-pick --help` lists them
    for add in (
        _add_evaluate_parser,
        _add_sweep_parser,
        _add_compare_parser,
        _add_design_parser,
        _add_robust_parser,
        _add_picks_parser,
        _add_calibrate_parser,
        _add_report_parser,
        _add_export_parser,
        _add_validate_parser,
        _add_listing_parsers,
        _add_cache_parser,
        _add_gui_parser,
        _add_trials_parser,
        _add_view_parser,
    ):
        add(sub)
    return ap


def _add_evaluate_parser(sub) -> None:
    """``mjx-pick evaluate``: simulate pick-points and write results."""
    ev = sub.add_parser("evaluate", help="simulate pick-points and write results")
    _add_object_args(ev)
    _add_gripper_args(ev)
    _add_physics_args(ev)
    _add_pick_args(ev, "pick-points to generate (Normal mode) (default: 1000; not with --picks)")
    _add_evaluate_output_args(ev)
    _add_grasp_source(ev)
    _add_optimization_args(ev)
    _add_progress(ev)
    _add_yes(ev)
    _add_ray(ev)
    _add_evaluate_checks(ev)
    ev.set_defaults(func=cmd_evaluate)


def _add_grasp_source(p: argparse.ArgumentParser) -> None:
    """Where a study's grasps come from (``studies.grasp_sources``)."""
    p.add_argument(
        "--grasps",
        default="topdown",
        metavar="topdown|antipodal|FILE",
        help="where the grasps come from: 'topdown' pick-points (default, the paper's), "
        "'antipodal' grasps on the part's mesh (any approach from above), or a grasp file "
        "(ACRONYM .h5, GraspGen .json, isaac_grasp .yaml, a CSV of 4x4 poses): every "
        "grasp in it, the infeasible left out (docs/formats.md) (default: topdown)",
    )
    p.add_argument(
        "--depth-mm",
        type=number("depth_mm", "--depth-mm"),
        help="with --grasps FILE: the grasp centre's distance from the gripper's base along "
        "the approach, where the file does not say (0: the poses are grasp centres)",
    )


def _add_evaluate_output_args(ev: argparse.ArgumentParser) -> None:
    """``evaluate``'s own pick-points, its output folder, chunks and traces."""
    ev.add_argument(
        "--picks",
        help="CSV of your own pick-points (columns x_mm, y_mm, yaw_deg), instead of --n",
    )
    ev.add_argument(
        "--skip-infeasible",
        action="store_true",
        help="leave infeasible rows of --picks out (listed) instead of refusing the file",
    )
    ev.add_argument(
        "--out",
        type=path_of("--out"),
        help="output folder (default: none: the summary is printed, nothing written)",
    )
    ev.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    _add_overwrite(ev)
    ev.add_argument(
        "--chunk-size",
        type=number("chunk_size", "--chunk-size"),
        help="pick-points per chunk saved while the run goes on, the unit of --resume "
        "(default: from device memory; one batch on the CPU)",
    )
    ev.add_argument(
        "--traces",
        type=number("n_traces", "--traces"),
        default=3,
        help="trace the n best and n worst pick-points (traces.parquet: force plots, "
        "animations, view)",
    )


def _add_optimization_args(ev: argparse.ArgumentParser) -> None:
    """``evaluate``'s Optimization mode: until K pick-points reach a score."""
    ev.add_argument(
        "--until",
        type=number("until", "--until"),
        metavar="K",
        help="Optimization mode: stop once K pick-points reach --min-score (default: off)",
    )
    ev.add_argument(
        "--min-score",
        type=number("min_score", "--min-score"),
        default=0.9,
        help="Optimization mode: the score, eq. (2) in [0, 1], a good pick-point reaches",
    )
    ev.add_argument(
        "--max",
        type=number("max_n", "--max"),
        help="Optimization mode: most pick-points to simulate (default: 10 x --until)",
    )


def _add_evaluate_checks(ev: argparse.ArgumentParser) -> None:
    """``evaluate``'s extra columns: minimum force, stability, step convergence."""
    ev.add_argument(
        "--min-force",
        action="store_true",
        help="add min_force_n, N: each pick-point's smallest successful F_d (bisection)",
    )
    ev.add_argument(
        "--stability-um",
        type=number("stability_um", "--stability-um"),
        default=0.0,
        help="simulate every pick-point again with the object moved this far along x, um "
        "(0-100; 0: off), and add label_stable: a label a micrometre flips rests on a "
        "threshold no engine reproduces reliably (default: 0.0)",
    )
    ev.add_argument(
        "--step-check",
        action="store_true",
        help="simulate every pick-point again at half the time step and add "
        "label_converged: a label the step changes is decided by the numerics",
    )


def _study_parser(
    sub, name: str, help_text: str, n_help: str | None = None
) -> argparse.ArgumentParser:
    """A study's parser (sweep, compare, design, robust) with the options they share:
    object, gripper, physics, pick-points, --out, --overwrite, --no-progress (n_help:
    as _add_pick_args')."""
    p = sub.add_parser(name, help=help_text)
    _add_object_args(p)
    _add_gripper_args(p)
    _add_physics_args(p)
    _add_pick_args(p, n_help)
    p.add_argument(
        "--out", type=path_of("--out"), help="output folder (default: none: nothing written)"
    )
    _add_overwrite(p)
    _add_progress(p)
    _add_yes(p)
    return p


def _add_sweep_parser(sub) -> None:
    """``mjx-pick sweep``."""
    sw = _study_parser(sub, "sweep", "sweep contact, controller, gripper or solver parameters")
    sw.add_argument(
        "--param",
        action="append",
        metavar="NAME=LO:HI:N",
        help="a swept parameter in its own unit (mjx-pick params): LO:HI:N grid, "
        "LO:HI:N:log geometric grid, A,B,C list, LO:HI range (--random); repeat",
    )
    sw.add_argument(
        "--random",
        type=number("random", "--random"),
        metavar="K",
        help="K random variants within the LO:HI ranges (default: the grid)",
    )
    _add_grasp_source(sw)
    _add_resume(sw)
    _add_ray(sw)
    sw.set_defaults(func=cmd_sweep, n=200)


def _add_compare_parser(sub) -> None:
    """``mjx-pick compare``."""
    cp = _study_parser(sub, "compare", "rank grippers on one shared pick-point set")
    cp.add_argument("--grippers", required=True, help="comma-separated presets or TOML files")
    cp.add_argument(
        "--rank-by",
        choices=("success", "score"),
        default="success",
        help="rank by success rate or by mean score, eq. (2)",
    )
    _add_resume(cp)
    _add_ray(cp)
    _add_grasp_source(cp)
    cp.set_defaults(func=cmd_compare, n=200)


def _add_design_parser(sub) -> None:
    """``mjx-pick design``."""
    ds = _study_parser(
        sub, "design", "search finger width, finger depth, stroke (any gripper field)"
    )
    ds.add_argument(
        "--bound",
        action="append",
        metavar="FIELD=LO:HI",
        help="a searched gripper field and its bounds in the field's unit (e.g. "
        "finger_width_mm=10:40; mjx-pick params gripper); repeat",
    )
    ds.add_argument(
        "--variants",
        type=number("variants", "--variants"),
        default=12,
        help="gripper variants sampled",
    )
    ds.add_argument(
        "--rounds",
        type=number("rounds", "--rounds"),
        default=3,
        help="successive-halving rounds (round r: n x 2^r pick-points, the best third kept)",
    )
    ds.add_argument(
        "--rank-by",
        choices=("success", "score"),
        default="success",
        help="rank by success rate or by mean score, eq. (2)",
    )
    _add_grasp_source(ds)
    _add_resume(ds)
    _add_ray(ds)
    ds.set_defaults(func=cmd_design, n=64)


def _add_robust_parser(sub) -> None:
    """``mjx-pick robust``."""
    rb = _study_parser(
        sub,
        "robust",
        "robust success probability of the top pick-points under vision error",
        "pick-points simulated first, to rank (default: 200; not with --results)",
    )
    rb.add_argument(
        "--results",
        help="an evaluate output folder or results.parquet to rank (default: simulate --n "
        "pick-points first)",
    )
    rb.add_argument(
        "--top-k",
        type=number("top_k", "--top-k"),
        default=10,
        help="best successful pick-points tested",
    )
    rb.add_argument(
        "--m", type=number("m", "--m"), default=32, help="perturbed draws per pick-point"
    )
    rb.add_argument(
        "--sigma-xy-mm",
        type=number("sigma_xy_mm", "--sigma-xy-mm"),
        default=2.0,
        help="vision error: standard deviation of x and y, mm",
    )
    rb.add_argument(
        "--sigma-yaw-deg",
        type=number("sigma_yaw_deg", "--sigma-yaw-deg"),
        default=3.0,
        help="vision error: standard deviation of yaw, deg",
    )
    _add_resume(rb)
    _add_ray(rb)
    _add_grasp_source(rb)
    rb.set_defaults(func=cmd_robust)


def _add_picks_parser(sub) -> None:
    """``mjx-pick picks``."""
    pk = sub.add_parser("picks", help="generate feasible pick-points and draw them")
    _add_object_args(pk)
    _add_gripper_args(pk)
    _add_pick_args(pk)
    pk.add_argument(
        "--out", type=path_of("--out"), required=True, help="output folder (picks.csv and pictures)"
    )
    _add_overwrite(pk)
    pk.set_defaults(func=cmd_picks)


def _add_calibrate_parser(sub) -> None:
    """``mjx-pick calibrate``: fit contact parameters to measured outcomes."""
    cb = sub.add_parser("calibrate", help="fit contact parameters to measured outcomes")
    cb.add_argument(
        "outcomes",
        help="measured outcomes CSV (format: mjx_pick/assets/outcomes/README.md), or physical "
        "trials (a TRIALS.csv, docs/formats.md: its grasps split by --split)",
    )
    _add_object_args(cb, required=False)
    cb.add_argument(
        "--split",
        type=number("split", "--split"),
        default=0.5,
        help="with a TRIALS.csv: the fraction of its grasps fitted (split by grasp, seeded "
        "by --seed); the rest are held out, validated before and after the fit "
        "(default: 0.5)",
    )
    _add_gripper_args(cb)
    _add_physics_args(cb)
    _add_pick_args(cb)
    _add_fitted_args(cb)
    _add_estimator_args(cb)
    cb.add_argument(
        "--replicates",
        type=number("replicates", "--replicates"),
        default=3,
        help="simulations of each row with a measured trace (the pick-point and copies "
        "0.05 mm off): their spread is the model's own uncertainty about a chaotic "
        "grasp's trace (docs/calibration.md); 1: one per row",
    )
    cb.add_argument(
        "--trace-window-s",
        type=number("trace_window_s", "--trace-window-s"),
        default=0.05,
        help="moving average over which measured and simulated traces are compared (s)",
    )
    cb.add_argument("--holdout", help="held-out outcomes CSV for accuracy before/after")
    cb.add_argument(
        "--force-mismatch",
        action="store_true",
        help="fit although the outcomes' record (OUTCOMES.toml beside the CSV) names another "
        "mass, gripper or procedure than this run (default: refused)",
    )
    cb.add_argument(
        "--no-identify",
        action="store_true",
        help="skip the intervals / identifiability after the fit",
    )
    cb.add_argument(
        "--checkpoint-every",
        type=number("checkpoint_every", "--checkpoint-every"),
        default=10,
        help="steps between saved checkpoints",
    )
    cb.add_argument(
        "--log-every",
        type=number("log_every", "--log-every"),
        default=10,
        help="steps between printed loss lines",
    )
    cb.add_argument(
        "--resume", action="store_true", help="continue an interrupted fit from its checkpoint"
    )
    cb.add_argument(
        "--out",
        type=path_of("--out"),
        required=True,
        help="output folder (contact.toml, loss.png, report.md, ...)",
    )
    _add_progress(cb)
    _add_yes(cb)
    cb.set_defaults(func=cmd_calibrate)


def _add_fitted_args(p: argparse.ArgumentParser) -> None:
    """calibrate's fitted parameters, their bounds and priors."""
    p.add_argument(
        "--params",
        default="pad_friction",
        help="comma-separated, fitted jointly: pad_friction, pad_torsion_mm, table_friction, "
        "pad_stiffness_n_per_mm, pad_damping_ns_per_mm, table_stiffness_n_per_mm, "
        "table_damping_ns_per_mm, force_offset_n (aliases: friction, torsion, stiffness, "
        "damping, force_offset)",
    )
    p.add_argument(
        "--bounds",
        action="append",
        metavar="NAME=LO:HI",
        help="a parameter's bounds in its own unit (N/mm, N s/mm, mm, N; repeatable)",
    )
    p.add_argument(
        "--prior",
        action="append",
        metavar="NAME=MEAN:SD",
        help="a parameter's Gaussian prior, its own unit (SD in natural-log units for "
        "stiffness, damping and torsion; default: mean the start, SD half the bounds; "
        "repeatable)",
    )


def _add_estimator_args(p: argparse.ArgumentParser) -> None:
    """calibrate's estimator and its steps, budget and smoothing."""
    p.add_argument(
        "--steps",
        type=number("steps", "--steps"),
        default=100,
        help="estimator steps (lsq: iterations)",
    )
    p.add_argument(
        "--budget",
        type=number("budget", "--budget"),
        help="stop after this many pick-point simulations (default: no limit)",
    )
    p.add_argument(
        "--lr",
        type=number("lr", "--lr"),
        default=0.1,
        help="Adam step, dimensionless: in the bounded space, whose range is 1 (smoothed, jvp)",
    )
    p.add_argument(
        "--estimator",
        choices=("smoothed", "random", "cma", "lsq", "jvp"),
        default="cma",
        help="cma: CMA-ES (docs/calibration.md says why it is the default); smoothed: "
        "Gauss-Hermite smoothed gradient + Adam; "
        "random: uniform search; lsq: Levenberg-Marquardt on the residuals "
        "(mujoco.sysid); jvp: forward mode through MJX",
    )
    p.add_argument(
        "--samples",
        type=number("samples", "--samples"),
        default=2,
        help="quadrature node pairs per parameter and step (smoothed)",
    )
    p.add_argument(
        "--sigma",
        type=number("sigma", "--sigma"),
        default=0.2,
        help="smoothing spread, dimensionless: in the bounded space, whose range is 1",
    )
    p.add_argument(
        "--temperature-mm",
        type=number("temperature_mm", "--temperature-mm"),
        default=2.0,
        help="outcome smoothing, mm of final lift",
    )


def _add_report_parser(sub) -> None:
    """``mjx-pick report``."""
    rp = sub.add_parser("report", help="plots, maps, animations, 1:1 template, robot export, HTML")
    rp.add_argument("run", help="an evaluate output folder")
    rp.add_argument(
        "--out", type=path_of("--out"), help="write here (default: into the run folder)"
    )
    rp.add_argument(
        "--n",
        type=number("report_n", "--n"),
        default=3,
        help="best and worst pick-points on the template",
    )
    rp.add_argument(
        "--k", type=number("report_k", "--k"), default=10, help="pick-points in the robot export"
    )
    rp.add_argument(
        "--frame",
        metavar="X,Y,Z,ROLL,PITCH,YAW",
        help="object frame's pose in your robot frame, mm and deg, for the export "
        "(default: the object frame)",
    )
    rp.add_argument(
        "--anim-every",
        type=number("anim_every", "--anim-every"),
        default=8,
        help="control ticks per animation frame (a tick: grasp.control_period_s)",
    )
    rp.add_argument(
        "--no-animations",
        action="store_true",
        help="skip the animations (GIF and MP4: the slowest part)",
    )
    _add_progress(rp)
    rp.set_defaults(func=cmd_report)


def _add_export_parser(sub) -> None:
    """``mjx-pick export``."""
    from mjx_pick.outputs.exchange import FORMATS

    ep = sub.add_parser(
        "export", help="the run's labels as ACRONYM, GraspGen or isaac_grasp grasp files"
    )
    ep.add_argument("run", help="an evaluate output folder")
    ep.add_argument("--format", required=True, choices=list(FORMATS), help="the grasp file format")
    ep.add_argument(
        "--out",
        type=path_of("--out"),
        help="the file to write (default: RUN/grasps_<format>.h5|.json|.yaml); the object's "
        "mesh goes beside it as <stem>_object.obj",
    )
    ep.add_argument(
        "--depth-mm",
        type=float,
        help="the gripper base's distance behind the grasp centre along the approach "
        "(GraspGen's depth; default: the simulated gripper's own)",
    )
    ep.add_argument("--overwrite", action="store_true", help="replace existing files")
    ep.set_defaults(func=cmd_export)


def _add_validate_parser(sub) -> None:
    """``mjx-pick validate``: labels against physical trials."""
    va = sub.add_parser(
        "validate",
        help="simulate the grasp of every physical trial of a TRIALS.csv and hold the labels "
        "against the real outcomes (accuracy, precision, recall, F1)",
    )
    va.add_argument(
        "trials",
        help="a TRIALS.csv: object, mass_g, gripper, object_pose, grasp_pose, depth_mm, "
        "success, trial (docs/formats.md)",
    )
    va.add_argument("--out", help="output folder (validation.json, trials.parquet)")
    _add_overwrite(va)
    va.add_argument(
        "--unit", choices=["m", "mm"], default="m", help="the length unit of the trials' meshes"
    )
    va.add_argument(
        "--seed", type=number("seed", "--seed"), default=0, help="seed of the intervals' bootstrap"
    )
    _add_physics_args(va)
    _add_yes(va)
    va.set_defaults(func=cmd_validate)


def _add_listing_parsers(sub) -> None:
    """``mjx-pick presets``, ``params`` and ``assets``: what can be chosen."""
    sub.add_parser("presets", help="list gripper presets").set_defaults(func=cmd_presets)
    pa = sub.add_parser(
        "params", help="each sweepable parameter: meaning, unit, default and allowed range"
    )
    pa.add_argument(
        "prefix",
        nargs="?",
        help="only parameters whose name starts with this (e.g. contact, grasp.lift)",
    )
    pa.set_defaults(func=cmd_params)
    sub.add_parser("assets", help="list shipped objects").set_defaults(func=cmd_assets)


def _add_cache_parser(sub) -> None:
    """``mjx-pick cache info | clear``."""
    ca = sub.add_parser(
        "cache",
        help="the cache of object preparation and compiled programs: where, how big, clear it",
    )
    steps = ca.add_subparsers(dest="step", required=True, parser_class=Parser)
    steps.add_parser(
        "info", help="its folder, entries, size and limit, and how to move or clear it"
    ).set_defaults(func=cmd_cache_info)
    steps.add_parser(
        "clear", help="delete every entry (object results and compiled programs)"
    ).set_defaults(func=cmd_cache_clear)


def _add_gui_parser(sub) -> None:
    gp = sub.add_parser("gui", help="the web GUI: the paper's four tabs and a sweep tab")
    gp.add_argument("--host", default="127.0.0.1", help="interface to listen on")
    gp.add_argument(
        "--port", type=number("port", "--port"), default=0, help="TCP port (0: a free one)"
    )
    gp.add_argument("--workdir", default="runs/gui", help="folder for uploads and runs")
    gp.add_argument("--no-browser", action="store_true", help="do not open a browser")
    gp.set_defaults(func=cmd_gui)


# ---------------------------------------------------------------------------- trials


def _add_trials_parser(sub) -> None:
    """``mjx-pick trials plan | record | agree | fit``: the paper's template-and-trial
    loop (docs/calibration.md, "Trials on the real cell")."""
    tp = sub.add_parser(
        "trials",
        help="the paper's loop on the real cell: plan pick-points and print their 1:1 "
        "templates, record outcomes, report agreement, fit and plan the next round",
    )
    steps = tp.add_subparsers(dest="step", required=True, parser_class=Parser)
    _add_trials_plan_parser(steps)
    _add_trials_record_agree_parsers(steps)
    _add_trials_fit_parser(steps)


def _add_trials_backend(p: argparse.ArgumentParser) -> None:
    """A trials step's --backend (as evaluate's, without its other run options)."""
    p.add_argument(
        "--backend",
        choices=registry.choices(),
        default=registry.AUTO,
        help="simulation backend (as evaluate)",
    )


def _add_trials_ranges(p: argparse.ArgumentParser) -> None:
    """A trials step's --bounds and --prior of the uncertain parameters."""
    p.add_argument("--bounds", action="append", metavar="NAME=LO:HI", help="a parameter's bounds")
    p.add_argument(
        "--prior",
        action="append",
        metavar="NAME=MEAN:SD",
        help="a parameter's Gaussian prior (SD in log units for stiffness, damping, "
        "torsion); what is known already: trials are then spent where doubt remains",
    )


def _add_trials_plan_parser(steps) -> None:
    """``mjx-pick trials plan``."""
    pl = steps.add_parser(
        "plan", help="choose pick-points of an evaluate run to try; print their 1:1 templates"
    )
    pl.add_argument("run", help="a finished evaluate output folder (its gripper and physics)")
    _add_object_args(pl)
    pl.add_argument("--n", type=number("trials_n", "--n"), default=12, help="pick-points to try")
    pl.add_argument(
        "--repeats",
        type=number("repeats", "--repeats"),
        default=5,
        help="trials per pick-point (the paper: 5)",
    )
    pl.add_argument(
        "--params",
        default="pad_friction",
        help="the uncertain parameters that decide what is informative (as calibrate --params)",
    )
    _add_trials_ranges(pl)
    _add_trials_placement_args(pl)
    _add_trials_choice_args(pl)
    pl.add_argument(
        "--paper", choices=("a4", "letter"), default="a4", help="paper size of the templates"
    )
    pl.add_argument(
        "--blind",
        action="store_true",
        help="keep the predictions out of trials.csv (the person at the robot does not see them)",
    )
    _add_trials_backend(pl)
    pl.add_argument(
        "--batch-size",
        type=number("batch_size", "--batch-size"),
        help="simulations per backend call",
    )
    pl.add_argument("--out", type=path_of("--out"), required=True, help="the trials folder")
    _add_overwrite(pl)
    pl.set_defaults(func=cmd_trials_plan)


def _add_trials_placement_args(pl: argparse.ArgumentParser) -> None:
    """``trials plan``'s parameter draws and the placing errors it simulates."""
    pl.add_argument(
        "--draws", type=number("draws", "--draws"), default=6, help="parameter draws from the prior"
    )
    pl.add_argument(
        "--placements",
        type=number("placements", "--placements"),
        default=3,
        help="placements per pick-point and draw: the template pose and jittered ones",
    )
    pl.add_argument(
        "--jitter-mm",
        type=number("jitter_mm", "--jitter-mm"),
        default=1.0,
        help="placing error on x and y, mm",
    )
    pl.add_argument(
        "--jitter-deg",
        type=number("jitter_deg", "--jitter-deg"),
        default=2.0,
        help="placing error on yaw, deg",
    )


def _add_trials_choice_args(pl: argparse.ArgumentParser) -> None:
    """``trials plan``'s candidates, how it chooses among them, and its seed."""
    pl.add_argument(
        "--pool",
        type=number("pool", "--pool"),
        default=32,
        help="candidates simulated, from the run's successes and failures",
    )
    pl.add_argument(
        "--info-share",
        type=number("info_share", "--info-share"),
        default=0.5,
        help="fraction chosen by expected information (the rest: best and worst, as the paper)",
    )
    pl.add_argument(
        "--seed",
        type=number("seed", "--seed"),
        default=0,
        help="seed of the parameter draws and placements",
    )


def _add_trials_record_agree_parsers(steps) -> None:
    """``mjx-pick trials record`` and ``trials agree``: the trials folder's rows."""
    rc = steps.add_parser(
        "record", help="ask for each untried row's successes at the terminal (blind)"
    )
    rc.add_argument("trials", help="a trials folder")
    rc.set_defaults(func=cmd_trials_record)

    ag = steps.add_parser(
        "agree", help="agreement of simulation and reality: confusion matrix, accuracy, per pick"
    )
    ag.add_argument("trials", help="a trials folder")
    ag.add_argument("--partial", action="store_true", help="use the tried rows, others blank")
    ag.set_defaults(func=cmd_trials_agree)


def _add_trials_fit_parser(steps) -> None:
    """``mjx-pick trials fit``."""
    ft = steps.add_parser(
        "fit",
        help="fit the outcomes, re-simulate, agreement before and after, plan the next round",
    )
    ft.add_argument("trials", help="a trials folder")
    _add_object_args(ft)
    ft.add_argument("--params", help="parameters to fit (default: the plan's --params)")
    _add_trials_ranges(ft)
    ft.add_argument("--steps", type=number("steps", "--steps"), default=40, help="estimator steps")
    ft.add_argument(
        "--estimator",
        choices=("cma", "smoothed", "random"),
        default="cma",
        help="as calibrate",
    )
    ft.add_argument(
        "--temperature-mm",
        type=number("temperature_mm", "--temperature-mm"),
        help="outcome smoothing, mm of final lift (default: as calibrate)",
    )
    ft.add_argument(
        "--next",
        type=number("next", "--next"),
        default=6,
        help="pick-points of the next round, where the fitted model is least sure (0: none)",
    )
    ft.add_argument("--partial", action="store_true", help="fit the tried rows, others blank")
    ft.add_argument(
        "--seed",
        type=number("seed", "--seed"),
        default=0,
        help="seed of the fit and of the next round's draws",
    )
    ft.add_argument("--no-identify", action="store_true", help="skip the intervals")
    ft.add_argument(
        "--paper", choices=("a4", "letter"), default="a4", help="paper size of the templates"
    )
    ft.add_argument(
        "--log-every",
        type=number("log_every", "--log-every"),
        default=10,
        help="steps between printed loss lines",
    )
    _add_trials_backend(ft)
    ft.add_argument("--resume", action="store_true", help="continue this round's fit")
    ft.add_argument("--overwrite", action="store_true", help="replace this round's earlier fit")
    ft.set_defaults(func=cmd_trials_fit)


def _add_view_parser(sub) -> None:
    vp = sub.add_parser(
        "view", help="replay one traced pick-point in MuJoCo's interactive viewer (a display)"
    )
    vp.add_argument("run", help="an evaluate output folder with traces.parquet")
    vp.add_argument(
        "--pick",
        required=True,
        metavar="ID",
        help="pick_id of a traced pick-point (the report's forces_<ID>.png), or best / worst: "
        "the best or worst traced one",
    )
    vp.add_argument(
        "--speed",
        type=number("speed", "--speed"),
        default=1.0,
        help="playback speed, a multiple of real time",
    )
    vp.add_argument("--loop", action="store_true", help="replay until the viewer window is closed")
    vp.set_defaults(func=cmd_view)
