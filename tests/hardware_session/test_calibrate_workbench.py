"""Calibrate mode through the REST API on hardware drivers: the RealSense driver playing the target's depth images,
the fake UR controller and the fake GRBL firmware (tests/devices/drivers/rigfixtures.py), as ``nbv serve --cell``
would drive them. The images are rendered from where the camera really is, ``T_table_camera @ E`` for each pose
(the cell file's hand-eye is off by E); every pose is previewed and approved (the fake arm and plate move), the
estimate is written into the cell file: the backup holds the old file and the new values are the estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.spatial.transform import Rotation

from app.main import create_app
from app.settings import AppSettings
from devices.arm.config import DEFAULT_T_FLANGE_CAMERA
from devices.calibration import pose_error
from devices.cellfile import load_cell_file
from devices.config import DeviceConfig
from planner.types import Pose
from tests.hardware_session.calibration_rig import ANGLES, CAMERA, calibration_rig

E = Pose(Rotation.from_rotvec([-0.007, 0.005, 0.006]).as_matrix(), np.array([-0.0025, 0.002, 0.001]))
"""The cell file's hand-eye error: the true camera is at ``T_flange_camera_file @ E``."""


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_calibrate_mode_on_the_fake_rig_approves_each_pose_and_writes_the_cell_file(tmp_path: Path) -> None:
    with calibration_rig(tmp_path, E) as (fake, poses):
        before = fake.path.read_text()
        settings = AppSettings(
            viser_port=0,
            scene=False,
            data_dir=tmp_path / "data",
            cell=str(fake.path),
            devices=DeviceConfig(camera=CAMERA),
        )
        with TestClient(create_app(settings), base_url="http://127.0.0.1") as client:
            created = client.post("/api/calibrations", json={"plate_angles_deg": list(ANGLES)})
            assert created.status_code == 201, created.text
            status = created.json()
            cid = status["id"]
            assert status["source"]["kind"] == "hardware" and status["writable"]
            assert [p["label"] for p in status["poses"]] == [p.label for p in poses]
            # a second holder of the devices is refused while the calibration has them
            session = client.post("/api/sessions", json={"model": "l-block", "source": {"kind": "hardware"}})
            assert session.status_code == 409, session.text
            for i in range(len(poses)):
                preview = client.post(f"/api/calibrations/{cid}/poses/{i}/preview").json()
                assert preview["reachable"] and len(preview["joints"]) == 6
                moves = len([c for c in fake.controller.calls if c[0] in ("moveJ", "servoJ")])
                approved = client.post(f"/api/calibrations/{cid}/poses/{i}/approve")
                assert approved.status_code == 200, approved.text
                pose = approved.json()["poses"][i]
                assert pose["status"] == "captured" and pose["spheres"] >= 3, pose
                assert len([c for c in fake.controller.calls if c[0] in ("moveJ", "servoJ")]) > moves  # it moved
            status = client.get(f"/api/calibrations/{cid}").json()
            estimate = status["estimate"]
            assert status["counts"] == {"pending": 0, "captured": len(poses), "skipped": 0}
            assert set(estimate["residuals_mm"]) == {p.label for p in poses}
            assert all(p["residual_mm"] is not None and p["residual_mm"] < 1.0 for p in status["poses"])
            written = client.post(f"/api/calibrations/{cid}/write")
            assert written.status_code == 200, written.text
            assert client.delete(f"/api/calibrations/{cid}").status_code == 204
    backup = Path(written.json()["backup"])
    assert backup.exists() and backup.read_text() == before and list(tmp_path.glob("cell.toml.*.bak")) == [backup]
    cell = load_cell_file(fake.path)
    X = Pose.from_matrix(np.array(estimate["T_flange_camera"]))
    mm, deg = pose_error(cell.hand_eye, X)
    assert mm < 1e-3 and deg < 1e-4  # the written values are the estimate (to the file's precision)
    mm, deg = pose_error(cell.hand_eye, Pose.from_matrix(np.array(DEFAULT_T_FLANGE_CAMERA)) @ E)
    assert mm < 0.3 and deg < 0.05, (mm, deg)  # and the estimate is the true hand-eye
    shift = np.array(estimate["axis_point"][:2])
    assert np.allclose(cell.arm_base.translation[:2], np.array([-0.85, 0.0]) - shift, atol=1e-6)
    assert np.allclose(cell.arm_base.translation, [-0.85, 0.0, 0.0], atol=3e-4)  # the plate axis was where it said
