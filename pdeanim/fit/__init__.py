"""Fitting poses with the dynamic-PDE model: the pipeline above the model (:mod:`pdeanim.model`) and the
curves (:mod:`pdeanim.curves`), from options to the two parts of a clip."""

from .options import FitOptions, FitTolerances
from .pipeline import curve_errors, fit_poses
from .report import target_shortfall

__all__ = ["FitOptions", "FitTolerances", "curve_errors", "fit_poses", "target_shortfall"]
