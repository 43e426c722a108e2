"""The kinematic :class:`devices.cell.Cell` on real devices: what a session drives on hardware.

:func:`hardware_cell` is the one builder: it puts the opened devices of a :class:`devices.rig.Rig` into a
:class:`HardwareCell`, the same ``Cell`` the simulator uses, with the arm model (``devices/arm``, the UR5 by
default) configured from the cell file (:func:`arm_cell_config`: the hand-eye transform, the arm's mount and
the driver's joint bounds; :func:`arm_kinematics`: planned joint speeds within the driver's limit). It checks
both that the model's joint names are the driver's and that the speeds fit, so a mismatch is refused before the
first move. :func:`dry_run_cell` builds the same cell on simulated devices (a rehearsal of the same scan).
Planning, IK, collision checks and trajectories then run on our side exactly as in simulation;
``Cell.move_to`` turns the real plate and sends the trajectory to the real arm, ``Cell.capture`` takes a real
image and places it by forward kinematics of the joints the controller reports. With move capture on
(``capture_hz``), the camera streams during the move and each frame is placed by the joint states at its stamp
(:mod:`devices.movestream`).

One holder at a time: :func:`device_claim` claims a cell file's devices for the block that opens them and hands
the claim to the cell, which releases it when it is closed (:class:`DevicesInUse` for a second claimant).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from devices.cell import Cell, Motion
from devices.cellfile import CellFile, T_table_base
from devices.config import CameraConfig, CellConfig
from devices.move_capture import MoveFrame, OnFrame
from devices.movestream import (
    FrameStreamer,
    JointRecorder,
    MoveStreamer,
    MoveStreamLimits,
    MoveStreamStats,
    PlateRecorder,
    PolledSeries,
    StampedSeries,
)
from devices.protocols import DeviceError
from devices.rig import Rig
from planner.types import DepthFrame, Pose
from planner.validate import finite

if TYPE_CHECKING:
    import trimesh

    from devices.arm.kinematics import ArmKinematics

log = logging.getLogger(__name__)

TURNTABLE_POLL_HZ = 50.0
"""Move capture: how often a turntable without stamped states (the Modbus drive) is read during a move."""


class DevicesInUse(RuntimeError):  # noqa: N818 - it says what the devices are
    """Another holder has the devices of this cell file open."""


_in_use: dict[str, str] = {}
"""Cell files whose devices a claim holds: resolved path -> label of the holder."""
_in_use_lock = threading.Lock()


class DeviceClaim:
    """The claim of one holder on the devices of a cell file; :meth:`release` (idempotent) lets them go."""

    def __init__(self, path: str, label: str) -> None:
        self.key = str(Path(path).resolve())
        with _in_use_lock:
            if self.key in _in_use:
                raise DevicesInUse(f"the devices of {path} are in use by {_in_use[self.key]}; delete or stop it first")
            _in_use[self.key] = label
        self._held = True

    def release(self) -> None:
        with _in_use_lock:
            if self._held:
                _in_use.pop(self.key, None)
                self._held = False


@contextmanager
def device_claim(path: str, label: str) -> Iterator[DeviceClaim]:
    """Claim the devices of cell file ``path`` for ``label`` while the block opens them: released when the block
    fails; after it, the claim belongs to whoever the block handed it to (a :class:`HardwareCell` releases it when
    closed). DevicesInUse when another holder has them."""
    claim = DeviceClaim(path, label)
    try:
        yield claim
    except BaseException:
        claim.release()
        raise


def arm_cell_config(cell: CellFile, base: CellConfig) -> CellConfig:
    """``base`` with the URDF arm model configured from the cell file (see the table in docs/hardware.md).

    ``T_flange_camera`` = the hand-eye transform, ``base`` / ``base_yaw_deg`` = the arm mount; with a UR arm
    also its joint limits and ``acceleration_limit_deg`` (at most ``max_joint_acceleration_deg``).
    ValueError naming the field (a tilted ``devices.arm_base``).
    """
    position, yaw = cell.arm_mount()
    changes: dict[str, Any] = {
        "T_flange_camera": tuple(tuple(float(v) for v in row) for row in cell.hand_eye.matrix),
        "base": position,
        "base_yaw_deg": yaw,
    }
    config = cell.arm.config if cell.arm is not None else None
    if config is not None and hasattr(config, "joint_lower_deg"):
        changes["joint_lower_deg"] = tuple(config.joint_lower_deg)
        changes["joint_upper_deg"] = tuple(config.joint_upper_deg)
    if config is not None and hasattr(config, "max_joint_acceleration_deg"):
        changes["acceleration_limit_deg"] = min(base.arm.acceleration_limit_deg, config.max_joint_acceleration_deg)
    if cell.move_capture_hz is not None:  # the cell file's rate of capture during moves wins over the server's
        base = dataclasses.replace(base, move_capture_hz=cell.move_capture_hz)
    return dataclasses.replace(base, kinematics="urdf", arm=dataclasses.replace(base.arm, **changes))


def arm_kinematics(cell: CellFile, config: CellConfig) -> tuple[CellConfig, ArmKinematics]:
    """(config, its arm model) with planned joint speeds within the cell file's ``max_joint_speed_deg``: the
    arm's ``velocity_scale`` is lowered when the URDF's limits times the scale would exceed it."""
    from devices.arm.kinematics import ArmKinematics

    kinematics = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)
    limit = getattr(cell.arm.config, "max_joint_speed_deg", None) if cell.arm is not None else None
    fastest = float(np.max(kinematics.model.velocity))
    if limit is not None and fastest > math.radians(limit):
        scale = config.arm.velocity_scale * math.radians(limit) / fastest * 0.999
        config = dataclasses.replace(config, arm=dataclasses.replace(config.arm, velocity_scale=scale))
        kinematics = ArmKinematics(config.arm, config.plate_radius, config.plate_thickness)
    return config, kinematics


def configured_arm(cell: CellFile, base: CellConfig) -> tuple[CellConfig, ArmKinematics]:
    """The cell config and arm model of a cell file: :func:`arm_cell_config` then :func:`arm_kinematics`."""
    return arm_kinematics(cell, arm_cell_config(cell, base))


class HardwareCell(Cell):
    """A :class:`Cell` on a cell file's devices (``rig``), or, in a dry run, on simulated devices.

    cellfile: the parsed cell file (``allow_auto``, hand-eye, mount). rig: the opened devices (None in a dry
    run). claim: this cell's claim on the devices (released by :meth:`close`).
    """

    def __init__(
        self,
        camera: Any,
        arm: Any,
        turntable: Any,
        config: CellConfig,
        *,
        kinematics: ArmKinematics,
        cellfile: CellFile,
        rig: Rig | None,
        claim: DeviceClaim | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(camera, arm, turntable, config, kinematics=kinematics, **kwargs)
        self.cellfile = cellfile
        self.rig = rig
        self.claim = claim
        self.moving = threading.Event()
        self.stop_requested = threading.Event()
        self._closed = False
        self._stream: MoveStreamer | None = None
        self._stream_closers: list[Callable[[], None]] = []
        self.last_move_stream: MoveStreamStats | None = None
        """What the move capture of the last move on real devices did (None: none ran)."""

    @property
    def dry_run(self) -> bool:
        return self.rig is None

    @property
    def pose(self) -> Pose:
        """``T_table_camera`` from the arm's forward kinematics and the plate angle, about the cell file's measured
        ``turntable_axis`` (a dry run simulates a vertical one). Planning keeps the vertical axis: at the 0.2
        degrees of tilt a calibration flags, a view lands within a millimetre of where it was planned."""
        if self.rig is None:
            return super().pose
        return T_table_base(self.turntable.angle, self.cellfile.turntable_axis) @ self.T_base_camera

    @property
    def allow_auto(self) -> bool:
        return self.cellfile.allow_auto

    def auto_refusal(self) -> str | None:
        """A real arm moves only on an approval per view unless the cell file says ``allow_auto = true``."""
        if self.allow_auto:
            return None
        where = self.cellfile.source or "the cell file"
        return (
            "step and auto mode would move the arm without an approval per view; "
            f"{where} does not allow it (set devices.allow_auto = true)"
        )

    def arm_state(self) -> str:
        """The arm's joints in degrees, or why they cannot be read (for error messages)."""
        try:
            q = self.arm.joint_positions()
        except DeviceError as exc:
            last = getattr(self.arm, "last_joint_positions", None)
            if last is None:
                return f"arm joints unknown ({exc})"
            q = last
        return "arm at joints [" + ", ".join(f"{math.degrees(float(v)):.2f}" for v in q) + "] deg"

    def move_to(
        self,
        T_table_camera: Pose,
        plate_angle: float | None = None,
        then: Sequence[Pose] = (),
        motion: Motion | None = None,
        capture_hz: float = 0.0,
        on_frame: OnFrame | None = None,
    ) -> Motion:
        """:meth:`Cell.move_to` (``plate_angle``, ``then``, ``motion``, ``capture_hz``, ``on_frame`` as there); a
        DeviceError (a fault, a refused trajectory, a stop) names the arm's last joints.

        On real devices with ``capture_hz`` > 0 the camera streams during the move: ``on_frame`` gets a MoveFrame
        for the frame nearest each ``1 / capture_hz`` tick, placed by the joint states at its stamp, in stamp order,
        from the stream's thread (:mod:`devices.movestream`; ``last_move_stream`` counts what it did). A fault of
        the stream never breaks the move; a halt ends it. ValueError for a bad ``capture_hz`` (nothing moved)."""
        if not (finite(capture_hz) and capture_hz >= 0):
            raise ValueError(f"capture_hz: must be >= 0 (0 = off), got {capture_hz!r}")
        self.stop_requested.clear()
        self.moving.set()
        try:
            if self.rig is not None and capture_hz > 0 and on_frame is not None:
                if motion is None or not self.reach.is_current(motion):  # planned before the stream starts: an
                    motion = self.plan_motion(T_table_camera, plate_angle, then)  # unreachable view streams nothing
                self._stream = self._stream_or_none(capture_hz, on_frame)
            # a dry run's simulated cell renders its move frames along the path; on real devices the stream does
            motion = super().move_to(T_table_camera, plate_angle, then, motion, capture_hz, on_frame)
            if self.stop_requested.is_set():
                raise DeviceError("stopped on request")
            return motion
        except DeviceError as exc:
            message = str(exc)
            if "last joints" not in message:
                message = f"{message}; {self.arm_state()}"
            exc.args = (message,)  # the same type and fields (ArmFaultError.joint_positions), a fuller message
            raise
        finally:
            self._end_stream()
            self.moving.clear()

    # ------------------------------------------------------------------ move capture on real devices

    def _stream_or_none(self, hz: float, on_frame: OnFrame) -> MoveStreamer | None:
        """:meth:`_start_stream`; a fault starting it (a device that cannot be read, a closed camera) is logged and
        counted, and the move runs without capture."""
        try:
            return self._start_stream(hz, on_frame)
        except Exception as exc:
            for close in self._stream_closers:
                close()
            self._stream_closers = []
            self.last_move_stream = MoveStreamStats(hz=hz, error=f"{type(exc).__name__}: {exc}")
            log.warning("move capture off for this move: the stream did not start (%s)", exc)
            return None

    def _start_stream(self, hz: float, on_frame: OnFrame) -> MoveStreamer | None:
        """The streamer of one move (None, logged, when this cell cannot stream: the move runs without it)."""
        stats = MoveStreamStats(hz=hz)
        self.last_move_stream = stats
        camera, kinematics = self.camera, self.kinematics
        if not isinstance(camera, FrameStreamer) or kinematics is None:
            stats.error = (
                "no arm model to place frames by"
                if kinematics is None
                else f"the {type(camera).__name__} camera driver does not stream frames"
            )
            log.warning("move capture off for this move: %s", stats.error)
            return None
        axis = self.cellfile.turntable_axis
        config = self.cellfile.camera.config if self.cellfile.camera is not None else None
        limits = MoveStreamLimits(
            max_gap_s=float(getattr(config, "move_capture_gap_s", MoveStreamLimits.max_gap_s)),
            wait_s=float(getattr(config, "move_capture_wait_s", MoveStreamLimits.wait_s)),
        )
        closers: list[Callable[[], None]] = []
        self._stream_closers = closers  # filled as the recordings start (a failure on the way closes them)
        joints, plate = self._histories(closers)
        t0 = joints.last_stamp
        if t0 is None:
            for close in closers:
                close()
            self._stream_closers = []
            stats.error = "no joint state to start from"
            log.warning("move capture off for this move: %s", stats.error)
            return None

        def pose_of(q: Any, theta: float) -> Pose:
            return T_table_base(theta, axis) @ kinematics.camera_pose(q)

        def deliver(frame: DepthFrame, t: float) -> None:
            on_frame(MoveFrame(frame=frame, t=t))

        streamer = MoveStreamer(camera.stream(), joints, plate, pose_of, t0, hz, deliver, limits)
        self.last_move_stream = streamer.stats
        return streamer

    def _histories(self, closers: list[Callable[[], None]]) -> tuple[StampedSeries, StampedSeries]:
        """(joints, plate angle), with what ends each recording appended to ``closers``: the drivers' stamped states where they have them (the
        ``ros2`` arm and turntable, the GRBL turntable's status reports), else the devices polled and stamped with
        the host clock (a UR arm at 200 Hz, a Modbus turntable at ``TURNTABLE_POLL_HZ``)."""
        arm, table = self.arm, self.turntable
        if isinstance(arm, JointRecorder):
            joints = arm.record_joints()
            closers.append(lambda: arm.stop_recording(joints))
        else:
            polled = PolledSeries(self.arm.joint_positions)
            joints = polled.series
            closers.append(polled.close)
        if isinstance(table, PlateRecorder):
            plate = table.record_plate()
            closers.append(lambda: table.stop_recording(plate))
        else:  # a driver whose reads may come from a second thread (the Modbus drive's bus is locked)
            polled_plate = PolledSeries(lambda: table.angle, hz=TURNTABLE_POLL_HZ, angle=True)
            plate = polled_plate.series
            closers.append(polled_plate.close)
        return joints, plate

    def _end_stream(self) -> None:
        """After the move (done, failed or halted): deliver the frames stamped up to its end, then stop recording."""
        streamer, self._stream = self._stream, None
        if streamer is None:
            return
        try:
            # the end marked on the history first: the streamer then knows it before finish() tells it
            end = None if self.stop_requested.is_set() else streamer.joints.end_move()
            stats = streamer.finish(end)
            log.info("%s", stats.summary())
        except Exception:  # never breaks the move
            log.exception("move capture: ending the stream failed")
        finally:
            closers, self._stream_closers = self._stream_closers, []
            for close in closers:
                close()

    def halt(self) -> list[str] | None:
        """Stop the arm and the turntable at once if a move is running (None when none is); the drivers' errors."""
        if not self.moving.is_set():
            return None
        self.stop_requested.set()
        streamer = self._stream
        if streamer is not None:
            streamer.stop()
        if self.rig is not None:
            return self.rig.stop()
        self.stop_moving()
        return []

    @property
    def halting(self) -> bool:
        return self.stop_requested.is_set()

    @property
    def noise_model(self) -> str:
        """The sensor model the planner assumes for this cell's camera: its config's ``noise_model`` ("ideal" for
        a camera driver without one)."""
        camera = self.cellfile.camera
        return str(getattr(camera.config, "noise_model", "ideal")) if camera is not None else "ideal"

    def restore_device_state(self, state: dict[str, Any]) -> None:
        """A resumed session on real devices moves nothing: the next plan starts from where they really are."""
        if self.dry_run:
            super().restore_device_state(state)

    def close(self) -> None:
        """Close the devices (once) and release the claim on them."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.rig is not None:
                self.rig.close()
        finally:
            if self.claim is not None:
                self.claim.release()


def hardware_cell(rig: Rig, cell_config: CellConfig | None = None, claim: DeviceClaim | None = None) -> HardwareCell:
    """A :class:`HardwareCell` of ``rig``'s camera, arm and turntable.

    cell_config: the plate, the initial view and the arm model (``cell_config.arm``: URDF, planning
    settings); its ``T_flange_camera``, ``base``, ``base_yaw_deg`` are replaced by the cell file's
    ``hand_eye`` and ``arm_base`` and, for a UR arm, its joint bounds by ``[devices.arm]``'s and its speeds
    kept within ``max_joint_speed_deg``, so plans and the driver agree. claim: handed to the cell (released
    when it closes). ValueError when a device is missing, the arm base is tilted, or the model's joints are
    not the driver's.
    """
    missing = [kind for kind in ("camera", "arm", "turntable") if getattr(rig, kind) is None]
    if missing:
        raise ValueError(f"devices.{missing[0]}: a cell needs a camera, an arm and a turntable")
    config, kinematics = configured_arm(rig.cell, cell_config if cell_config is not None else CellConfig())
    if tuple(kinematics.joint_names) != tuple(rig.arm.joint_names):
        raise ValueError(
            f"devices.arm: the arm model's joints {list(kinematics.joint_names)} are not the driver's "
            f"{list(rig.arm.joint_names)}"
        )
    return HardwareCell(
        rig.camera, rig.arm, rig.turntable, config, kinematics=kinematics, cellfile=rig.cell, rig=rig, claim=claim
    )


def open_hardware_cell(cellfile: CellFile, cell_config: CellConfig, label: str) -> HardwareCell:
    """Claim the devices of ``cellfile`` for ``label``, open them and build their :func:`hardware_cell`.

    DevicesInUse when another holder has them; DeviceError / OSError when a device cannot be opened;
    ValueError for a bad cell file (a missing device, a tilted mount, joints that are not the driver's). On
    any failure the devices opened so far are closed and the claim released."""
    from devices.rig import open_rig

    missing = [kind for kind in ("camera", "arm", "turntable") if getattr(cellfile, kind) is None]
    if missing:
        raise ValueError(f"devices.{missing[0]}: a hardware session needs a camera, an arm and a turntable")
    configured_arm(cellfile, cell_config)  # a bad mount is refused before any device opens
    with device_claim(str(cellfile.source), label) as claim:
        rig = open_rig(cellfile)
        try:
            return hardware_cell(rig, cell_config, claim)
        except BaseException:
            rig.close()
            raise


def dry_run_cell(
    cellfile: CellFile, cell_config: CellConfig, mesh: trimesh.Trimesh | None, camera: CameraConfig, seed: int
) -> HardwareCell:
    """The cell of a dry run: the simulator scanning ``mesh`` with ``camera``, with the cell file's arm model (no
    device opened). ValueError for a bad cell file."""
    from devices.sim import make_sim_cell

    config, _ = configured_arm(cellfile, cell_config)
    sim = make_sim_cell(mesh, camera, config, seed=seed)
    assert sim.kinematics is not None
    cell = HardwareCell(
        sim.camera,
        sim.arm,
        sim.turntable,
        config,
        kinematics=sim.kinematics,
        cellfile=cellfile,
        rig=None,
        pose_noise_translation=camera.pose_noise_translation,
        pose_noise_rotation_deg=camera.pose_noise_rotation_deg,
        seed=seed,
    )
    cell.move_capture = sim.move_capture  # a dry run renders its move frames as the simulator does
    return cell
