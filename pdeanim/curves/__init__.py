"""Automatic curve extraction: partition a mesh's vertices into smooth ordered curves for the PDE fit."""

from .extract import extract_curves

__all__ = ["extract_curves"]
