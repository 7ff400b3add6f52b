"""Every physical setting of one simulated variant: gripper, contact, solver, procedure."""

from __future__ import annotations

import dataclasses
from collections.abc import Collection

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.procedure import GraspConfig


@dataclasses.dataclass(frozen=True)
class Settings:
    """The settings one variant is simulated with.

    Evaluate, sweeps, gripper comparisons, design searches, robustness and calibration
    all run (Settings, GraspBatch) jobs; ``engine.inputs`` turns them into a scene and
    each pick-point's inputs. The procedure's control period is checked against the
    solver's time step here, once, when the settings are made.
    """

    gripper: GripperSpec = dataclasses.field(default_factory=GripperSpec)
    contact: ContactParams = dataclasses.field(default_factory=ContactParams)
    solver: SolverParams = dataclasses.field(default_factory=SolverParams)
    grasp: GraspConfig = dataclasses.field(default_factory=GraspConfig)

    def __post_init__(self):
        self.grasp.substeps(self.solver)  # a whole number of steps per control period

    def structure(self) -> tuple:
        """What fixes the compiled scene: gripper, solver, scan length, grasp height and
        the contact settings that shape the model (the pads' collision geoms and
        margin). Everything else (the other contact numbers, controller, phases) is
        per-pick data; scenes of one model structure also share a compiled program,
        their differing model fields carried per pick (``engine.variants.program_key``)."""
        return (
            self.gripper,
            self.solver,
            self.contact.pad_collision,
            self.contact.pad_margin_mm,
            self.grasp.n_ticks(),
            self.grasp.substeps(self.solver),
            self.grasp.grasp_height,
            self.grasp.fingertip_clearance_mm,
        )

    def on_gripper(
        self, gripper: GripperSpec, keep: Collection[str] = ()
    ) -> tuple[Settings, str | None]:
        """These settings on `gripper`, the procedure fitted to its ranges
        (``GraspConfig.fitted_to``; keep: the procedure fields the user set), and the
        note saying what moved (None: nothing)."""
        grasp, note = self.grasp.fitted_to(gripper, keep)
        return dataclasses.replace(self, gripper=gripper, grasp=grasp), note
