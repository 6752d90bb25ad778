"""The site estimator's network and model file.

:class:`SiteNet` takes a stereo pair (left and right RGB stacked, 6 x 96 x 128) plus two pixel-coordinate
channels, and returns the three grasp sites in the left camera frame. Four 3 x 3 convolutions (two of
stride 2) lead to 32 feature maps at a quarter of the resolution; a spatial soft-argmax turns each
into the expected image position of its activation (keypoints, as in Levine et al.'s visuomotor
policies: precise to a fraction of a pixel with few weights), which a small MLP maps, with the maps'
pooled features, to 9 coordinates. 38,000 weights: the model file is 0.16 MB.

The model file is a safetensors file of tensors only, with the endoscope it was trained for, the label
normalisation and its training report in the metadata.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file
from torch import nn

from policies.errors import CheckpointError
from policies.perception.frames import stereo_input
from psm_control.errors import InputFileError
from psm_control.inputs import check_regular_file
from psm_control.outputs import atomic_path
from sim.endoscope import Endoscope, StereoFrame

__all__ = ["SHIPPED_MODEL", "SHIPPED_MODELS", "SiteEstimator", "SiteNet", "load_estimator"]

#: The model shipped with the package (trained by ``tissue-retract train-perception`` on the tasks' pink flaps).
SHIPPED_MODEL = Path(__file__).resolve().parent / "site-estimator.safetensors"
#: The shipped models by the name ``--perception camera:NAME`` takes: ``any-colour`` was trained by
#: ``train-perception --any-colour`` on flaps of any colour, for a flap that does not look like the tasks'.
SHIPPED_MODELS = {
    "pink": SHIPPED_MODEL,
    "any-colour": SHIPPED_MODEL.with_name("site-estimator-any-colour.safetensors"),
}
_FORMAT = "tissue-retract-site-estimator"
_MAX_FILE_BYTES = 64 * 1024 * 1024


class SiteNet(nn.Module):
    """Stereo pair -> three sites in the left camera frame (normalised units).

    Args:
        width: Channels of the first convolution (the others follow from it).
        keypoints: Feature maps turned into keypoints.
    """

    def __init__(self, width: int = 16, keypoints: int = 32) -> None:
        super().__init__()
        w = width

        def block(cin: int, cout: int, stride: int) -> list[nn.Module]:
            return [nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)]

        self.features = nn.Sequential(
            *block(8, w, 2), *block(w, 2 * w, 2), *block(2 * w, 2 * w, 1), *block(2 * w, keypoints, 1)
        )
        self.temperature = nn.Parameter(torch.ones(1))
        self.head = nn.Sequential(nn.Linear(3 * keypoints, 128), nn.ReLU(inplace=True), nn.Linear(128, 9))
        self.width, self.keypoints = width, keypoints

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 6, H, W) uint8 or float in [0, 255] -> (B, 9)."""
        x = images.float() / 255.0 - 0.5
        batch, _, height, width = x.shape
        ys = torch.linspace(-1.0, 1.0, height, device=x.device).view(1, 1, height, 1).expand(batch, 1, height, width)
        xs = torch.linspace(-1.0, 1.0, width, device=x.device).view(1, 1, 1, width).expand(batch, 1, height, width)
        maps = self.features(torch.cat([x, xs, ys], dim=1))
        b, k, h, w = maps.shape
        weights = torch.softmax(maps.view(b, k, h * w) / self.temperature, dim=2).view(b, k, h, w)
        grid_y = torch.linspace(-1.0, 1.0, h, device=x.device).view(1, 1, h, 1)
        grid_x = torch.linspace(-1.0, 1.0, w, device=x.device).view(1, 1, 1, w)
        points = torch.cat([(weights * grid_x).sum(dim=(2, 3)), (weights * grid_y).sum(dim=(2, 3))], dim=1)
        pooled = maps.mean(dim=(2, 3))
        return self.head(torch.cat([points, pooled], dim=1))


class SiteEstimator:
    """A trained :class:`SiteNet` with what it needs to give sites in the world.

    Args:
        net: The network (put in evaluation mode here).
        endoscope: The endoscope its frames came from.
        label_mean_m: (9,) mean of the training labels [m].
        label_scale_m: Scale of the normalised labels [m].
        info: The training report and settings (``mark_sites``, errors, commands).
    """

    def __init__(
        self, net: SiteNet, endoscope: Endoscope, label_mean_m: np.ndarray, label_scale_m: float, info: dict[str, Any]
    ) -> None:
        self.net = net.eval()
        self.endoscope = endoscope
        self.label_mean_m = np.asarray(label_mean_m, dtype=float)
        self.label_scale_m = float(label_scale_m)
        self.info = dict(info)

    @property
    def mark_sites(self) -> bool:
        """Whether it was trained on flaps with inked sites."""
        return bool(self.info.get("mark_sites", False))

    def camera_sites(self, images: np.ndarray, batch: int = 256) -> np.ndarray:
        """(N, 6, H, W) uint8 stereo inputs -> (N, 3, 3) sites in the left camera frame [m]."""
        out = []
        with torch.no_grad():
            for start in range(0, len(images), batch):
                chunk = torch.from_numpy(np.ascontiguousarray(images[start : start + batch]))
                out.append(self.net(chunk).numpy().astype(float))
        normalised = np.concatenate(out) if out else np.zeros((0, 9))
        return (normalised * self.label_scale_m + self.label_mean_m).reshape(-1, 3, 3)

    def world_sites(self, frame: StereoFrame, site: str | None = None) -> np.ndarray:
        """The three sites (3, 3) in the world [m] (``sim.tissue.SITE_NAMES`` order) from one frame.

        ``site`` (the one a run grasps) is for estimators that choose by it (:class:`~policies.perception.
        chooser.SiteChooser`); one network estimates all three alike.
        """
        camera = self.camera_sites(stereo_input(frame)[None])[0]
        pose = frame.world_from_camera
        return np.asarray(camera @ pose[:3, :3].T + pose[:3, 3])

    def save(self, path: str | Path) -> Path:
        """Write the model file (tensors only; settings in the metadata)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {
            "format": _FORMAT,
            "width": self.net.width,
            "keypoints": self.net.keypoints,
            "endoscope": asdict(self.endoscope),
            "label_mean_m": self.label_mean_m.tolist(),
            "label_scale_m": self.label_scale_m,
            "info": self.info,
        }
        tensors = {k: v.detach().contiguous() for k, v in self.net.state_dict().items()}
        with atomic_path(path, "--out") as temporary:
            save_file(tensors, str(temporary), metadata={"site_estimator": json.dumps(meta)})
        return path


def _check_tensors(path: Path, net: SiteNet, tensors: dict[str, torch.Tensor]) -> None:
    """The file's tensors are the network's, name for name and shape for shape, or a :class:`CheckpointError`."""
    expected = {name: tuple(t.shape) for name, t in net.state_dict().items()}
    given = {name: tuple(t.shape) for name, t in tensors.items()}
    network = f"the network of width {net.width} with {net.keypoints} keypoints the metadata names"
    missing, extra = sorted(expected.keys() - given.keys()), sorted(given.keys() - expected.keys())
    if missing or extra:
        found = f"missing {', '.join(missing[:3])}" if missing else f"unexpected {', '.join(extra[:3])}"
        raise CheckpointError(path, f"not a site estimator's model file: its tensors are not {network} ({found})")
    for name, shape in expected.items():
        if given[name] != shape:
            raise CheckpointError(
                path,
                f"not a site estimator's model file: tensor {name} is {list(given[name])}, expected {list(shape)} "
                f"for {network}",
            )


def load_estimator(path: str | Path | None = None) -> SiteEstimator:
    """Read a model file (default: the shipped one; a name of :data:`SHIPPED_MODELS`: that shipped one)
    without executing anything from it.

    Raises:
        CheckpointError: The file is missing, not a safetensors file, or not a site estimator's.
    """
    path = SHIPPED_MODEL if path is None else SHIPPED_MODELS.get(str(path), Path(path))
    if not path.exists():
        raise CheckpointError(path, "no such file")
    try:
        check_regular_file(path, "--perception", _MAX_FILE_BYTES)
    except InputFileError as e:
        raise CheckpointError(path, f"not a usable file: expected {e.allowed}") from e
    try:
        with safe_open(str(path), framework="pt") as handle:
            raw = (handle.metadata() or {}).get("site_estimator")
            tensors = {name: handle.get_tensor(name) for name in handle.keys()}  # noqa: SIM118 (not a dict)
    except (SafetensorError, OSError, ValueError) as e:
        raise CheckpointError(path, f"not a safetensors site estimator: {e}") from e
    if not raw:
        raise CheckpointError(
            path,
            "not a site estimator's model file: a safetensors file without the site_estimator metadata "
            "train-perception writes",
        )
    try:
        meta = json.loads(raw)
        if not isinstance(meta, dict) or meta.get("format") != _FORMAT:
            raise ValueError(f"its site_estimator metadata is not of the format {_FORMAT!r}")
        net = SiteNet(int(meta["width"]), int(meta["keypoints"]))
        _check_tensors(path, net, tensors)
        net.load_state_dict(tensors)
        fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in meta["endoscope"].items()}
        endoscope = Endoscope(**fields)
        estimator = SiteEstimator(
            net, endoscope, np.asarray(meta["label_mean_m"], dtype=float), float(meta["label_scale_m"]), meta["info"]
        )
    except (ValueError, KeyError, TypeError, RuntimeError, AttributeError) as e:
        raise CheckpointError(path, f"not a site estimator's model file: {str(e).splitlines()[0]}") from e
    if not all(torch.isfinite(t).all() for t in tensors.values() if t.is_floating_point()):
        raise CheckpointError(path, "non-finite weights")
    return estimator
