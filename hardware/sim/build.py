"""Assemble the simulated rig for one setup: world, skin model, device twins, virtual clock."""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np

from hardware.interfaces import DeviceError
from hardware.rig import Rig
from hardware.sim.arm import SimArm
from hardware.sim.camera import SimMarkerCamera
from hardware.sim.clock import SimClock
from hardware.sim.ft import SimForceTorque
from hardware.sim.gripper import SimGripper
from hardware.sim.platform import SimPlatform
from hardware.sim.skin import SimSkinReader
from layerskin_exp.config import SkinConfig
from layerskin_exp.rig import R_TCP_SKIN
from layerskin_exp.sim import compile_notice
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.clocks import device_rng
from layerskin_exp.sim.grip_scene import GripScene
from layerskin_exp.sim.platform_scene import PlatformScene
from layerskin_exp.sim.world import World

SETUPS = ("platform", "gripper")


@dataclass
class SimRig(Rig):
    """The simulated rig: every twin observes one World; the clock is virtual.

    extras["world"] is the World (for tests, benchmarks and the realtime emulators; protocols
    must not use it). trial_hooks(labels) run at each begin_trial: the world draws the trial's
    noise and bench variation from the seed and the labels.

    A trial is determined by its identity, not by the trials before it: with fresh_trials, each
    begin_trial puts the world and every twin back into the state they had at the first one
    (stage or arm where they started, skin at rest, streams at their first phase, counters at
    zero), so a trial replays the same whether it runs first, after others or after a resume.
    The realtime world (loopback) keeps one running world instead: it cannot step back in time.

    Dates: the run starts at run_start_ns (Unix ns: sim.rig.start_time, else the wall clock when
    the rig was built); a trial's first host time is dated run_start_ns + its slot_s.
    """

    extras: dict = field(default_factory=dict)
    trial_hooks: list[Callable[[dict], None]] = field(default_factory=list)
    fresh_trials: bool = True
    run_start_ns: int = 0
    start_how: str = ""  # where run_start_ns came from, for the sessions' "log_time" record
    _first_state: dict | None = field(default=None, init=False, repr=False)
    _log_time: tuple[int, str] | None = field(default=None, init=False, repr=False)

    def begin_trial(self, labels: dict, slot_s: float = 0.0) -> None:
        if self.fresh_trials:
            if self._first_state is None:
                self._take_first_state()
            else:
                self._restore_first_state()
        for hook in self.trial_hooks:
            hook(dict(labels))
        offset = self.run_start_ns + round(slot_s * 1e9) - self.clock.now_ns()
        self._log_time = (offset, f"simulated: run start {_iso(self.run_start_ns)} ({self.start_how}) + trial "
                                  f"slot {slot_s:g} s")

    def log_time(self) -> tuple[int, str] | None:
        return self._log_time

    def _state_objects(self) -> list:
        """What holds the simulation's state and is referenced from outside it (restored in place)."""
        world = self.extras["world"]
        return [world, world.scene, world.skin_model, *self.devices()]

    def _keep(self) -> dict:
        """deepcopy memo: objects shared as they are (the rig; the camera's imager, a cache of
        pure renderings that holds OpenCV objects)."""
        keep = [self] + ([self.camera.imager] if self.camera is not None else [])
        return {id(o): o for o in keep}

    def _copy(self, objs: list, dicts: list[dict]) -> list[dict]:
        """A deep copy of dicts (the objs' __dict__s) in which references to objs stay references."""
        return copy.deepcopy(dicts, self._keep() | {id(o): o for o in objs})

    def _take_first_state(self) -> None:
        objs = self._state_objects()
        self._first_state = {"objs": objs, "dicts": self._copy(objs, [o.__dict__ for o in objs])}

    def _restore_first_state(self) -> None:
        objs = self._first_state["objs"]
        for o, d in zip(objs, self._copy(objs, self._first_state["dicts"]), strict=True):
            o.__dict__.clear()
            o.__dict__.update(d)


def _iso(unix_ns: int) -> str:
    return datetime.fromtimestamp(unix_ns / 1e9, timezone.utc).isoformat(timespec="milliseconds")


def _default_skin_model(sim_cfg, skin_cfg, indenter, rng, support_stiffness_n_per_mm):
    from layerskin_exp.sim.skin import SkinModel

    return SkinModel(sim_cfg, skin_cfg, indenter, rng, support_stiffness_n_per_mm=support_stiffness_n_per_mm)


def build_sim_rig(sim_cfg, skin_cfg: SkinConfig, setup: str, skin_model_factory: Callable | None = None) -> SimRig:
    """The simulated rig for `setup` ("platform" or "gripper"), deterministic under sim_cfg.seed.

    sim_cfg: SimConfig (seed, rig parameters, skin physics); skin_cfg: SkinConfig.
    skin_model_factory(sim_cfg, skin_cfg, indenter, rng, support_stiffness_n_per_mm) builds the
    skin mechanics (default: layerskin_exp.sim.skin.SkinModel).
    Returns a SimRig (rig.extras["world"] is the World).
    """
    if setup not in SETUPS:
        raise DeviceError(f"sim: unknown setup {setup!r}; choose one of {SETUPS}")
    notice = compile_notice.install()  # before the first kernel compiles (the skin model's)
    rc = sim_cfg.rig
    scene = PlatformScene(rc.platform) if setup == "platform" else GripScene(rc.arm, rc.gripper)
    factory = skin_model_factory or _default_skin_model
    model = factory(sim_cfg, skin_cfg, scene.indenter, device_rng(sim_cfg.seed, "skin_model"),
                    scene.support_stiffness_n_per_mm)
    world = World(rc, skin_cfg, sim_cfg.seed, scene, model)
    clock = SimClock(world)
    skin = SimSkinReader(world, rc.skin)
    rig = SimRig(backend="sim", clock=clock, skin=skin, extras={"world": world, "setup": setup},
                 run_start_ns=rc.run_start_ns(),
                 start_how="wall clock" if rc.start_time is None else "sim.rig.start_time")
    # Skin guards act at the end of each world advance (at most one control tick late); F/T
    # guards act on the very sample, rewinding the world to it (see SimForceTorque).
    skin.on_frames = rig.check_frames
    rig.trial_hooks.append(world.begin_trial)
    rig.trial_hooks.append(notice.report)
    if setup == "platform":
        rig.ft = SimForceTorque(world, rc.ft, device_rng(sim_cfg.seed, "ft"), on_sample=rig.check_guards,
                                 probe=rig.guard_reason)
        rig.platform = SimPlatform(world, scene, rc.platform)
    else:
        rig.arm = SimArm(world, scene, rc.arm)
        rig.gripper = SimGripper(world, scene, rc.gripper)
        rig.camera = SimMarkerCamera(world, scene, rc.camera, rc.gripper.contact_opening_mm)
        rig.extras["camera"] = rig.camera.calibration()
        rig.extras["skin_in_tcp"] = {
            "rotation": scene_rotation_doc(),
            "translation_axis_tcp": [1.0, 0.0, 0.0],
            "torsion_axis_tcp": [0.0, 1.0, 0.0],
        }
    warm_kernels(rig)
    return rig


def warm_kernels(rig: SimRig) -> None:
    """Load from numba's disk cache (on a fresh install: compile) the kernels a trial calls that
    building the rig did not, now, before any trial: the stage's motion planner runs only once
    something moves, and the F/T and clock kernels only at the first world advance. Inside a
    trial that took the realtime world's lock for as long as the compile (seen on loopback after a
    fresh install: "skin stalled: no frame for 57 ms"). Each runs on a copy, so the rig's state
    and random draws are those it would have without this."""
    world = rig.extras["world"]
    scene = copy.deepcopy(world.scene)
    if isinstance(scene, PlatformScene):
        scene.command_move(np.asarray(scene.stage.position, float) + [0.0, 0.0, 0.1], 1.0)
    scene.plan(2, world.mech_dt_s)
    scene.indenter_pose()
    if rig.ft is not None:
        copy.deepcopy(rig.ft.synth).readings(np.zeros((1, mk.STEP_FIELDS)), np.zeros(1, np.int64))
    copy.deepcopy(rig.skin.stream.clock).stamp(np.zeros(1))


def scene_rotation_doc() -> list[list[float]]:
    """Skin axes in the TCP frame (columns x_s, y_s, z_s), as nested lists for metadata."""
    return R_TCP_SKIN.tolist()
