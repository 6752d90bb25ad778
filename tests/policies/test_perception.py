"""The site estimator: labelled frames, a short training run, its model file, and refusals."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from policies.errors import CheckpointError
from policies.perception import SHIPPED_MODEL, SHIPPED_MODELS, SiteEstimator, SiteNet, load_estimator, render_frames
from policies.perception.frames import ANY_COLOUR
from policies.perception.training import error_stats_mm, train_site_estimator
from sim.endoscope import Endoscope
from sim.robustness import parse_vary, training_ranges


def test_frames_label_the_sites_in_the_camera_frame() -> None:
    """Labels lie in front of the camera, project inside the image, and differ from the named places by the offset."""
    frames = render_frames("multisite", [11, 12], frames_per_reset=2)
    assert frames.images.shape == (4, 6, 96, 128) and frames.images.dtype == np.uint8
    endoscope = Endoscope()
    pixels = frames.sites_camera_m @ endoscope.intrinsics().T
    u, v = pixels[..., 0] / pixels[..., 2], pixels[..., 1] / pixels[..., 2]
    assert np.all(frames.sites_camera_m[..., 2] > 0.05)
    assert np.all((u > 0) & (u < endoscope.width) & (v > 0) & (v < endoscope.height))
    offsets_mm = 1000 * np.linalg.norm(frames.sites_camera_m - frames.named_camera_m, axis=-1)
    assert np.all(offsets_mm <= np.hypot(3.0, 2.0) + 0.5)
    # Two frames of one reset share the sites in the world, not the images (their appearances differ).
    assert np.abs(frames.images[0].astype(int) - frames.images[1].astype(int)).mean() > 2.0


def _site_colours(randomization: dict[str, tuple[float, float]] | None) -> np.ndarray:
    """The left eye's RGB at the centre site of eight flaps (8, 3)."""
    frames = render_frames("lift", list(range(21, 29)), frames_per_reset=1, randomization=randomization)
    pixels = frames.sites_camera_m[:, 0] @ Endoscope().intrinsics().T
    u, v = (pixels[:, 0] / pixels[:, 2]).astype(int), (pixels[:, 1] / pixels[:, 2]).astype(int)
    return frames.images[np.arange(8), :3, v, u].astype(float)


def test_any_colour_frames_show_flaps_the_tasks_pink_never_does() -> None:
    """With ANY_COLOUR some flaps are greener than red at the site; the tasks' own flaps never are."""
    pink, any_colour = _site_colours(None), _site_colours(ANY_COLOUR)
    assert np.all(pink[:, 0] > pink[:, 1])
    assert np.any(any_colour[:, 1] > any_colour[:, 0])


def _flap_pixels(vary: str) -> np.ndarray:
    """How many of the left eye's pixels show the (pink) flap, on four flaps drawn over ``vary``'s ranges."""
    ranges = training_ranges(parse_vary(vary))
    frames = render_frames(
        "multisite", list(range(31, 35)), frames_per_reset=1, randomization=ranges.randomization,
        log_uniform=ranges.log_uniform,
    )  # fmt: skip
    left = frames.images[:, :3].astype(int)
    return np.asarray(((left[:, 0] - left[:, 1]) > 40).sum(axis=(1, 2)))


def test_frames_over_a_sweeps_ranges_show_its_flaps() -> None:
    """train-perception --vary renders the flaps a sweep meets: the same four flaps at the sweep's largest size
    (1.2 x) cover about (1.2 / 0.8)^2 = 2.25 x the image they cover at its smallest (measured 2.2-2.6 x)."""
    small, large = _flap_pixels("size=0.8:0.8x"), _flap_pixels("size=1.2:1.2x")
    assert np.all(large > 1.8 * small) and np.all(large < 3.0 * small), (small, large)


def test_error_stats_are_distances_in_mm() -> None:
    """Median and p95 of point distances, in millimetres."""
    estimated = np.zeros((4, 3, 3))
    true = np.zeros((4, 3, 3))
    true[..., 0] = 0.002
    assert error_stats_mm(estimated, true) == pytest.approx((2.0, 2.0))


def test_a_short_training_learns_and_its_model_file_round_trips(tmp_path: Path) -> None:
    """A 25 s budget renders, trains and measures; the saved model loads and gives the same estimates."""
    started = time.monotonic()
    estimator, report = train_site_estimator(
        "multisite", budget_s=25.0, started_s=started, heldout=12, progress=lambda _: None
    )
    assert report.train_frames > 0 and report.epochs >= 1
    assert np.isfinite(report.median_mm) and report.floor_median_mm > 0
    frames = render_frames("multisite", [91_000_000 + i for i in range(12)], frames_per_reset=1)
    path = estimator.save(tmp_path / "model.safetensors")
    loaded = load_estimator(path)
    np.testing.assert_allclose(loaded.camera_sites(frames.images), estimator.camera_sites(frames.images), atol=1e-9)
    assert loaded.endoscope == estimator.endoscope and loaded.info["report"]["median_mm"] == report.median_mm


@pytest.mark.parametrize("name", [None, "any-colour"])
def test_the_shipped_models_are_small_and_their_recorded_error_holds_on_other_frames(name: str | None) -> None:
    """Each shipped model is under 5 MB; on 40 flaps it never saw (of any colour for ``any-colour``), its median
    error is within 1 mm of its record."""
    estimator = load_estimator(name)
    any_colour = name == "any-colour"
    assert estimator.info.get("any_colour", False) == any_colour
    assert (SHIPPED_MODELS["any-colour"] if any_colour else SHIPPED_MODEL).stat().st_size < 5e6
    frames = render_frames(
        "multisite",
        [93_000_000 + i for i in range(40)],
        frames_per_reset=1,
        randomization=ANY_COLOUR if any_colour else None,
    )
    median, _ = error_stats_mm(estimator.camera_sites(frames.images), frames.sites_camera_m)
    assert abs(median - estimator.info["report"]["median_mm"]) < 1.0, (median, estimator.info["report"])


def test_a_pickle_is_refused(tmp_path: Path) -> None:
    """A pickle is refused with a CheckpointError, nothing executed (an empty or garbage file is a row of
    tests/test_hostile_inputs.py)."""
    path = tmp_path / "model.safetensors"
    path.write_bytes(b"\x80\x04pickle")
    with pytest.raises(CheckpointError):
        load_estimator(path)


def test_non_finite_weights_are_refused(tmp_path: Path) -> None:
    """A model file with a NaN weight is refused."""
    net = SiteNet()
    with torch.no_grad():
        net.head[0].weight[0, 0] = float("nan")
    path = SiteEstimator(net, Endoscope(), np.zeros(9), 0.01, {}).save(tmp_path / "nan.safetensors")
    with pytest.raises(CheckpointError, match="non-finite"):
        load_estimator(path)


def test_a_safetensors_file_without_the_estimators_metadata_is_named(tmp_path: Path) -> None:
    """Tensors without the site_estimator metadata: the error says what is missing, not a JSON parser's words."""
    path = tmp_path / "plain.safetensors"
    save_file({"w": torch.zeros(3)}, str(path))
    with pytest.raises(CheckpointError, match="without the site_estimator metadata") as caught:
        load_estimator(path)
    assert "Expecting value" not in str(caught.value)


def test_a_model_file_of_another_shape_names_the_tensor_and_both_shapes(tmp_path: Path) -> None:
    """Metadata for one network, tensors of another: the first mismatched tensor with its shape and the expected one."""
    path = SiteEstimator(SiteNet(width=8), Endoscope(), np.zeros(9), 0.01, {}).save(tmp_path / "narrow.safetensors")
    with safe_open(str(path), framework="pt") as handle:
        metadata = handle.metadata()
        tensors = {name: handle.get_tensor(name) for name in handle.keys()}  # noqa: SIM118 (not a dict)
    meta = json.loads(metadata["site_estimator"])
    meta["width"] = 16  # the file now claims the shipped width
    save_file(tensors, str(path), metadata={"site_estimator": json.dumps(meta)})
    with pytest.raises(CheckpointError) as caught:
        load_estimator(path)
    message = str(caught.value)
    assert "tensor features.0.weight is [8, 8, 3, 3], expected [16, 8, 3, 3]" in message, message
    assert "width 16 with 32 keypoints" in message, message


@pytest.mark.parametrize(
    ("texture", "chosen", "at_least"),
    [(None, "pink", 6), ("tests/data/textures/checker-blue.png", "any-colour", 10)],
)
def test_the_default_estimator_takes_the_pink_one_on_pink_flaps_and_the_any_colour_one_elsewhere(
    texture: str | None, chosen: str, at_least: int
) -> None:
    """``--perception camera``: on the tasks' flaps the two shipped estimators agree and the pink one's site is
    taken; on a checkerboard flap the pink one misses by centimetres, and the any-colour one's is taken."""
    import sim.envs
    from hardware_if.client.perceived_env import camera_task
    from sim.tissue import TissueParams

    env = camera_task(sim.envs.make("multisite", tissue=TissueParams(texture_path=texture)))
    try:
        infos = [env.reset(seed=seed)[1] for seed in range(2000, 2010)]
    finally:
        env.close()
    assert sum(info["site_estimator"] == chosen for info in infos) >= at_least, [i["site_estimator"] for i in infos]
    assert np.median([info["site_error_mm"] for info in infos]) < 5.0


def test_the_chooser_reads_the_flaps_colour_about_the_sites_in_view() -> None:
    """``flap_red_over_green``: the mean colour about the sites the camera sees; NaN when it sees none."""
    from policies.perception.chooser import flap_red_over_green
    from sim.endoscope import StereoFrame

    left = np.zeros((96, 128, 3), dtype=np.uint8)
    left[:, :64] = (200, 100, 100)  # a pink left half, a green right half
    left[:, 64:] = (60, 160, 60)
    intrinsics = np.array([[100.0, 0.0, 64.0], [0.0, 100.0, 48.0], [0.0, 0.0, 1.0]])
    frame = StereoFrame(left, left, np.eye(4), intrinsics, 0.005, np.ones((96, 128)), np.zeros((96, 128), int))
    pink_site, green_site = np.array([-0.02, 0.0, 0.1]), np.array([0.02, 0.0, 0.1])  # 20 px either side
    assert flap_red_over_green(frame, pink_site[None]) == pytest.approx(0.25)
    assert flap_red_over_green(frame, green_site[None]) == pytest.approx(-100 / 280)
    behind, outside = np.array([0.0, 0.0, -0.1]), np.array([1.0, 0.0, 0.1])
    assert flap_red_over_green(frame, np.stack([pink_site, behind, outside])) == pytest.approx(0.25)
    assert np.isnan(flap_red_over_green(frame, np.stack([behind, outside])))
