"""Collision checks of the arm (Pinocchio + coal): its links and camera against the plate, the table, the object
and themselves.

Obstacles, in the base frame with the plate at angle theta:

- ``plate``: the turntable, a cylinder of ``plate_radius`` from the table (or the plate's underside) up to z = 0;
- ``table``: the half-space below ``ArmConfig.table_height`` (none when it is 0);
- ``object``: a conservative model of the scanned object, the box B of the map (table frame) padded by
  ``ArmConfig.object_padding``, turned with the plate (:meth:`CollisionWorld.set_object_box`).

Link meshes are replaced by their convex hulls (conservative: a hull contains its mesh; and GJK on hulls is
about 50 times faster than mesh BVHs against the boxes). The arm's root link is not checked against the obstacles (it stands on its own pedestal); self collisions are
checked between every two geometries that are neither on the same or adjacent joints nor disabled by the SRDF.
A collision is reported as ``collision:<link>:<obstacle>`` (the obstacle a link name for self collisions).
"""

from __future__ import annotations

import math
import re
import threading

import numpy as np
from numpy.typing import NDArray

from devices.arm.model import ArmModel

_HULL_LOCK = threading.Lock()

FAR_AWAY = np.array([0.0, 0.0, -1e3])
"""Where the object box waits while there is no object model (nothing collides with it there)."""


class CollisionWorld:
    """The arm and its obstacles; not thread-safe (one per cell; it keeps Pinocchio data buffers).

    arm: the loaded arm. plate_radius, plate_thickness: the turntable (``CellConfig``), metres.
    """

    def __init__(self, arm: ArmModel, plate_radius: float, plate_thickness: float) -> None:
        import coal  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        self.arm = arm
        self.plate = (float(plate_radius), float(plate_thickness))
        """(radius, thickness) of the turntable, metres: with ``arm``, what the world's fixed obstacles are made of."""
        model = arm.model
        geometry = arm.geometry.copy()
        self._arm_geoms = list(range(geometry.ngeoms))
        with _HULL_LOCK:  # the meshes are shared with the (cached) arm model and other worlds
            for i in self._arm_geoms:  # convex hulls: conservative, and ~50x faster than mesh BVHs against boxes
                mesh = geometry.geometryObjects[i].geometry
                if isinstance(mesh, coal.BVHModelBase):
                    if mesh.convex is None:
                        mesh.buildConvexHull(True, "Qt")
                    geometry.geometryObjects[i].geometry = mesh.convex
        table = arm.config.table_height
        bottom = min(table, -plate_thickness) if table < 0 else -plate_thickness
        plate = pin.GeometryObject(
            "plate",
            0,
            pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.5 * bottom])),
            coal.Cylinder(plate_radius, -bottom),
        )
        obstacles = [geometry.addGeometryObject(plate)]
        if table < 0:
            table_geom = coal.Halfspace(np.array([0.0, 0.0, 1.0]), table)
            obstacles.append(geometry.addGeometryObject(pin.GeometryObject("table", 0, pin.SE3.Identity(), table_geom)))
        self._object = geometry.addGeometryObject(
            pin.GeometryObject("object", 0, pin.SE3(np.eye(3), FAR_AWAY), coal.Box(1e-3, 1e-3, 1e-3))
        )
        obstacles.append(self._object)

        joints = [geometry.geometryObjects[i].parentJoint for i in self._arm_geoms]
        for a in self._arm_geoms:
            for b in self._arm_geoms[a + 1 :]:
                ja, jb = joints[a], joints[b]
                if ja == jb or model.parents[ja] == jb or model.parents[jb] == ja:
                    continue
                geometry.addCollisionPair(pin.CollisionPair(a, b))
        if arm.srdf_path is not None:
            pin.removeCollisionPairs(model, geometry, str(arm.srdf_path))
        for a in self._arm_geoms:
            if joints[a] == 0:
                continue
            for o in obstacles:
                geometry.addCollisionPair(pin.CollisionPair(a, o))
        self.geometry = geometry
        self.names = [_link_name(geometry.geometryObjects[i].name) for i in range(geometry.ngeoms)]
        self._data = model.createData()
        self._gdata = pin.GeometryData(geometry)
        self._box_center_table = FAR_AWAY.copy()
        self.box: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        self._sweep: object | None = None  # the cylinder the padded box sweeps as the plate turns (coal.Cylinder)
        self._sweep_z = 0.0
        self._sweep_geoms = [i for i in self._arm_geoms if joints[i] != 0]
        pairs = [(p.first, p.second) for p in geometry.collisionPairs]
        self._object_pairs = [k for k, pair in enumerate(pairs) if self._object in pair]  # in the pairs' order
        self._fixed_pairs = [k for k, pair in enumerate(pairs) if self._object not in pair]
        self._placed: bytes | None = None  # the configuration turning_collision placed the arm at (None: another since)
        self._fixed_first: tuple[bytes, int | None] | None = None  # (configuration, its first colliding fixed pair)

    @property
    def pair_count(self) -> int:
        """How many geometry pairs each check tests."""
        return len(self.geometry.collisionPairs)

    def set_object_box(self, lower_table: NDArray[np.float64] | None, upper_table: NDArray[np.float64] | None) -> None:
        """The object's box in the table frame, (3,) corners, metres (padded here); None = no object model."""
        import coal  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        if lower_table is None or upper_table is None:
            self.box = None
            self._box_center_table = FAR_AWAY.copy()
            self._sweep = None
            return
        lo = np.asarray(lower_table, dtype=np.float64) - self.arm.config.object_padding
        hi = np.asarray(upper_table, dtype=np.float64) + self.arm.config.object_padding
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo) & np.isfinite(hi)) or np.any(hi <= lo):
            raise ValueError(
                f"object box: need finite (3,) corners with lower < upper, got {lower_table!r}, {upper_table!r}"
            )
        if self.box is not None and np.array_equal(self.box[0], lo) and np.array_equal(self.box[1], hi):
            return
        self.box = (lo, hi)
        self._box_center_table = 0.5 * (lo + hi)
        self.geometry.geometryObjects[self._object].geometry = coal.Box(*(hi - lo))
        self._gdata = pin.GeometryData(self.geometry)
        self._placed = self._fixed_first = None
        corners_xy = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
        self._sweep = coal.Cylinder(float(np.max(np.linalg.norm(corners_xy, axis=1))), float(hi[2] - lo[2]))
        self._sweep_z = float(0.5 * (lo[2] + hi[2]))

    def sweep_free(self, q: NDArray[np.float64]) -> bool:
        """Whether configuration (n,) ``q`` is free (self, plate, table) and clear of the vertical cylinder about
        the plate's axis that holds the padded object box at every plate angle: then no turn of the plate can
        bring the box into the arm standing at ``q`` (a sufficient test; False says nothing). False without a box
        model only if ``q`` itself collides."""
        import coal  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        if self.collision(q, 0.0) is not None:  # places the geometries at q (the box's angle is irrelevant below)
            return False
        if self._sweep is None:
            return True
        where = coal.Transform3s(np.eye(3), np.array([0.0, 0.0, self._sweep_z]))
        request, objects = coal.CollisionRequest(), self.geometry.geometryObjects
        for i in self._sweep_geoms:
            result = coal.CollisionResult()
            placement = self._gdata.oMg[i]
            tf = coal.Transform3s(placement.rotation, placement.translation)
            if coal.collide(objects[i].geometry, tf, self._sweep, where, request, result):
                return False
        return True

    def collision(self, q: NDArray[np.float64], plate_angle: float) -> str | None:
        """None when configuration (n,) ``q`` with the plate at ``plate_angle`` (rad) is free, else the reason."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        self._place(q, plate_angle)
        if not pin.computeCollisions(self.geometry, self._gdata, True):
            return None
        for k, result in enumerate(self._gdata.collisionResults):
            if result.isCollision():
                return self._reason(k)
        return "collision:unknown:unknown"  # pragma: no cover - computeCollisions said yes

    def turning_collision(self, q: NDArray[np.float64], plate_angle: float) -> str | None:
        """:meth:`collision` of a configuration asked at many plate angles (a turn's grid of checks): the same answer.
        Only the object's box moves with the plate, so the other pairs (the arm with itself, the plate, the table) are
        checked once per configuration and only the box's pairs at each angle, in the pairs' order (the first
        collision in that order is the reason, as :meth:`collision` reports it)."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        key = q.tobytes()
        if self._placed != key:
            pin.updateGeometryPlacements(self.arm.model, self._data, self.geometry, self._gdata, q)
            self._placed = key
        if self._fixed_first is None or self._fixed_first[0] != key:
            first = next((k for k in self._fixed_pairs if pin.computeCollision(self.geometry, self._gdata, k)), None)
            self._fixed_first = (key, first)
        fixed = self._fixed_first[1]
        self._gdata.oMg[self._object] = self._object_placement(plate_angle)
        for k in self._object_pairs:
            if fixed is not None and k > fixed:
                break
            if pin.computeCollision(self.geometry, self._gdata, k):
                return self._reason(k)
        return None if fixed is None else self._reason(fixed)

    def _reason(self, k: int) -> str:
        pair = self.geometry.collisionPairs[k]
        return f"collision:{self.names[pair.first]}:{self.names[pair.second]}"

    def path_collision(
        self, qa: NDArray[np.float64], qb: NDArray[np.float64], plate_angle: float, resolution: float
    ) -> str | None:
        """The first collision on the straight joint-space segment qa -> qb (both ends included), checked every
        ``resolution`` radians of the largest joint step; None if free."""
        steps = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / resolution))
        for t in np.linspace(0.0, 1.0, steps + 1):
            reason = self.collision(qa + t * (qb - qa), plate_angle)
            if reason is not None:
                return reason
        return None

    def _place(self, q: NDArray[np.float64], plate_angle: float) -> None:
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        pin.updateGeometryPlacements(self.arm.model, self._data, self.geometry, self._gdata, q)
        self._placed = None  # placed by a full check: turning_collision places its configuration again
        self._gdata.oMg[self._object] = self._object_placement(plate_angle)

    def _object_placement(self, plate_angle: float) -> object:
        """The object box's placement (pin.SE3) with the plate at ``plate_angle``."""
        import pinocchio as pin  # pyright: ignore[reportMissingImports]  (under cmeel.prefix)

        c, s = math.cos(plate_angle), math.sin(plate_angle)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return pin.SE3(R, R @ self._box_center_table)


def _link_name(geometry_name: str) -> str:
    """'forearm_link_0' -> 'forearm_link' (Pinocchio numbers the collision geometries of a link)."""
    return re.sub(r"_\d+$", "", geometry_name)
