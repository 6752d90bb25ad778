"""The options that put the endoscope in a command: ``--texture FILE.png`` and ``--perception camera[:MODEL]``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from psm_control.errors import ConfigurationError, InputFileError
from psm_control.inputs import check_regular_file

if TYPE_CHECKING:
    from sim.tissue import TissueParams

__all__ = [
    "add_perception_argument",
    "add_texture_argument",
    "check_texture",
    "load_perception",
    "texture_warning",
    "tissue_params",
]

_MAX_TEXTURE_BYTES = 32 * 1024 * 1024
_MAX_TEXTURE_PX = 8192


def check_texture(path: str) -> str:
    """A readable PNG or JPEG image file of at most 8192 px a side, or a :class:`ConfigurationError`."""
    check_regular_file(path, "--texture", _MAX_TEXTURE_BYTES)
    from PIL import Image, UnidentifiedImageError  # Pillow comes with matplotlib and imageio

    allowed = f"a PNG or JPEG image of at most {_MAX_TEXTURE_PX} px a side"
    try:
        with Image.open(path) as picture:
            if picture.format not in ("PNG", "JPEG"):
                raise InputFileError("--texture", path, f"{allowed} (this is {picture.format})")
            if max(picture.size) > _MAX_TEXTURE_PX or min(picture.size) < 1:
                raise InputFileError("--texture", path, f"{allowed} (this is {picture.size[0]} x {picture.size[1]})")
            picture.convert("RGB").load()
    except InputFileError:
        raise
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as e:
        raise InputFileError("--texture", path, f"{allowed} ({e})") from e
    return str(Path(path).resolve())


def add_texture_argument(parser: argparse.ArgumentParser) -> None:
    """``--texture FILE.png``: the flap's texture from an image file."""
    parser.add_argument(
        "--texture",
        metavar="FILE.png",
        default=None,
        help="the flap's texture from an image (PNG or JPEG), e.g. a photo of your phantom, in its own colours",
    )


def add_perception_argument(parser: argparse.ArgumentParser) -> None:
    """``--perception camera[:MODEL]``: the site from the endoscope's images."""
    parser.add_argument(
        "--perception",
        metavar="camera[:MODEL]",
        default=None,
        help="Tasks I-III: the observation's site from the site estimator on the endoscope's stereo images "
        "(MODEL: a train-perception model file; pink or any-colour: the shipped one trained on the tasks' pink "
        "flaps, or on flaps of any colour; default: both shipped ones, the pink one's site where the flap about it "
        "looks pink, else the any-colour one's), a jaw-sensed grasp",
    )


def load_perception(value: str | None) -> Any:
    """The site estimator that ``--perception`` names (None without it; see ``load_site_estimator``)."""
    if value is None:
        return None
    kind, _, model = value.partition(":")
    if kind != "camera":
        raise ConfigurationError(
            "--perception", value, "camera or camera:MODEL (a train-perception model file, pink or any-colour)"
        )
    from policies.perception import load_site_estimator  # torch: only when the camera is used

    return load_site_estimator(model or None)


def tissue_params(texture: str | None) -> TissueParams:
    """The flap's settings with the texture file ``--texture`` names (checked)."""
    from sim.tissue import TissueParams  # PyBullet: only for a command that builds a flap

    return TissueParams(texture_path=check_texture(texture) if texture is not None else None)


def texture_warning(estimator: Any, texture: str | None) -> str:
    """What to tell a user whose flap shows an image unlike anything the site estimator saw ('' if nothing).

    An estimator trained on the tasks' pink flaps only (neither ``--any-colour`` nor ``--texture``) keys on
    their colour: on three unseen textures it missed the site by 14-45 mm (median; docs/perception.md).
    """
    if estimator is None or texture is None or estimator.info.get("any_colour") or estimator.info.get("textures"):
        return ""
    return (
        f"WARNING: the flap shows {Path(texture).name}, but the site estimator was trained on the tasks' pink flaps "
        "only: on a flap that looks otherwise it can miss the site by centimetres. Use --perception camera (it "
        "takes the any-colour estimator where the flap does not look pink), camera:any-colour, or a model from "
        "train-perception --texture on photographs of this flap."
    )
