"""A scene's registration record reads back exactly what the catalog keeps: its camera models and
Sim3 as records, and the JSON they came from unchanged (an empty model map included)."""

from __future__ import annotations

import numpy as np

from siteline.camera.pinhole import CameraModel
from siteline.camera.poses import Sim3
from siteline.records.registration import Registration

COLMAP = {
    "source": "colmap",
    "images": 3,
    "camera_models": {
        "1": {
            "model": "OPENCV", "width": 660, "height": 495, "params": [500.0, 501.0, 330.0, 247.5, 0.01, -0.02, 0.0, 0.0],
            "undistorted": {"model": "PINHOLE", "width": 650, "height": 490, "params": [500.0, 501.0, 325.0, 245.0]},
        },
        "2": None,
    },
    "residuals_m": {"a.jpg": 0.01, "b.jpg": 0.02, "c.jpg": 0.015},
    "rms_m": 0.0153,
    "site_from_model": {
        "scale": 2.5, "rotation": [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        "translation": [445000.125, 5030000.25, 80.5],
    },
}  # fmt: skip


def test_a_colmap_registration_reads_as_records_and_writes_back_the_same_json() -> None:
    reg = Registration.from_dict(COLMAP)
    assert reg.camera_models is not None
    model = reg.camera_models["1"]
    assert isinstance(model, CameraModel) and model.undistorted is not None
    assert (model.model, model.undistorted.model, model.undistorted.width) == ("OPENCV", "PINHOLE", 650)
    assert reg.camera_models["2"] is None
    sim = reg.site_from_model
    assert isinstance(sim, Sim3) and sim.name == "site_from_model"
    # exact at georeferenced magnitudes: the model's origin lands on the site's millions of metres
    assert np.array_equal(sim.apply(np.zeros((1, 3))), [[445000.125, 5030000.25, 80.5]])
    assert reg.to_dict() == COLMAP


def test_an_empty_model_map_and_a_bare_record_round_trip() -> None:
    empty = {"source": "colmap", "images": 0, "camera_models": {}}
    assert Registration.from_dict(empty).to_dict() == empty
    assert Registration.from_dict({}).to_dict() == {"source": "unknown"}
