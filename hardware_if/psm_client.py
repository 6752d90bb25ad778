"""The old path of :mod:`hardware_if.client.psm_client`, kept for user scripts; the project imports from there."""

from hardware_if.client.psm_client import PsmClient

__all__ = ["PsmClient"]
