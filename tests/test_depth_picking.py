"""Frame picker decisions: baseline window, rotation, epipoles, sharpness, partner choice."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from layerpilot.depth import FramePicker, PickConfig
from layerpilot.eval.fixtures import noise_texture
from layerpilot.geometry import CameraFrame, CameraIntrinsics
from layerpilot.camera import camera_pose

K = CameraIntrinsics.from_fov(160, 120, 60.0)
IMAGE = cv2.resize(noise_texture(256, seed=1), (160, 120), interpolation=cv2.INTER_AREA)
BLURRY = cv2.GaussianBlur(IMAGE, (0, 0), 6)


def frame(x=0.0, y=0.0, z=40.0, yaw=90.0, pitch=90.0, stamp=0.0, image=IMAGE) -> CameraFrame:
    return CameraFrame(image, camera_pose(np.array([x, y, z]), np.radians(yaw), pitch), K, stamp)


def picker(**kw) -> FramePicker:
    return FramePicker(PickConfig(**kw))  # nadir from 40 m over ground z = 0: scene depth 40 m


def test_first_frame_has_no_partner():
    p = picker()
    assert p.push(frame()).reason == "no_history"
    assert p.skipped["no_history"] == 1


def test_sideways_baseline_in_window_is_accepted():
    p = picker(min_baseline_ratio=0.03, max_baseline_ratio=0.1)
    first = frame(x=0.0)
    p.push(first)
    res = p.push(frame(x=2.0, stamp=1.0))  # 2 m / 40 m = 0.05
    assert res.reason == "ok" and res.partner is first
    assert res.scene_depth == pytest.approx(40.0) and res.baseline_ratio == pytest.approx(0.05)


@pytest.mark.parametrize("dx, reason", [(0.4, "baseline_short"), (8.0, "baseline_long")])
def test_baseline_outside_window_is_skipped(dx, reason):
    p = picker(min_baseline_ratio=0.03, max_baseline_ratio=0.1)
    p.push(frame())
    assert p.push(frame(x=dx)).reason == reason
    assert p.skipped[reason] == 1


def test_large_relative_rotation_is_skipped():
    p = picker(max_rotation_deg=10.0)
    p.push(frame(yaw=90.0))
    assert p.push(frame(x=2.0, yaw=110.0)).reason == "rotation"


def test_motion_along_the_optical_axis_puts_the_epipole_inside():
    p = picker()
    p.push(frame(z=40.0))
    # nadir camera descending 2 m: epipole at the image centre
    assert p.push(frame(z=38.0)).reason == "epipole_inside"
    # camera 15 deg below the horizon (scene depth capped at 100 m) flying forward: epipole in the image
    p2 = picker()
    p2.push(frame(x=0.0, yaw=0.0, pitch=15.0))
    assert p2.push(frame(x=4.0, yaw=0.0, pitch=15.0)).reason == "epipole_inside"
    # the same camera flying sideways (along its x axis) is fine
    p3 = picker()
    p3.push(frame(y=0.0, yaw=0.0, pitch=15.0))
    assert p3.push(frame(y=-4.0, yaw=0.0, pitch=15.0)).reason == "ok"


def test_blurry_frame_is_skipped_and_never_a_partner():
    p = picker()
    p.push(frame(x=0.0))
    assert p.push(frame(x=1.0, image=BLURRY)).reason == "blurry"
    res = p.push(frame(x=2.0))
    assert res.reason == "ok" and res.partner.pose.position[0] == 0.0
    assert dict(p.skipped) == {"no_history": 1, "blurry": 1} and p.pairs == 1


def test_partner_nearest_the_target_ratio_wins():
    p = picker(min_baseline_ratio=0.02, max_baseline_ratio=0.12, target_baseline_ratio=0.06)
    for i, x in enumerate([0.0, 0.8, 1.6, 2.4, 3.2]):
        p.push(frame(x=x, stamp=i))
    res = p.push(frame(x=4.0, stamp=5))
    assert res.reason == "ok" and res.partner.pose.position[0] == pytest.approx(1.6)  # 2.4 m / 40 m = 0.06


def test_reason_is_from_the_candidate_that_got_furthest():
    p = picker(max_rotation_deg=5.0)
    p.push(frame(x=0.0, yaw=90.0))     # right baseline, rotated: fails at the rotation check
    p.push(frame(x=1.9, yaw=120.0))
    res = p.push(frame(x=2.0, yaw=120.0))  # nearest candidate fails earlier (baseline too short)
    assert res.reason == "rotation"


def test_scene_depth_from_a_callback_and_history_length():
    p = FramePicker(PickConfig(history=2), scene_depth=lambda f: 20.0)
    for x in (0.0, 0.1, 0.2):
        p.push(frame(x=x))
    res = p.push(frame(x=0.65))  # only x=0 (0.65 / 20 > 0.03) would do, and it fell out of the history
    assert res.scene_depth == 20.0 and res.reason == "baseline_short"


def test_config_errors_name_the_key():
    with pytest.raises(ValueError, match="max_baseline_ratio"):
        PickConfig(min_baseline_ratio=0.1, max_baseline_ratio=0.05)


def test_partner_of_another_image_size_is_not_used():
    p = picker()
    small = cv2.resize(IMAGE, (80, 60), interpolation=cv2.INTER_AREA)
    p.push(CameraFrame(small, camera_pose(np.array([0.0, 0.0, 40.0]), np.radians(90.0), 90.0),
                       CameraIntrinsics.from_fov(80, 60, 60.0), 0.0))
    assert p.push(frame(x=2.0)).reason == "size_mismatch"
