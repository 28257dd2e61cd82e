"""The residual loop: find the residual, trace it to a physical effect, add it, report."""

from ._checks import apparent_ratio as apparent_ratio, check_inputs as check_inputs
from ._library import (
    FAMILIES as FAMILIES,
    Candidate as Candidate,
    LibraryOptions as LibraryOptions,
    build_library as build_library,
)
from ._loop import (
    DiscoverOptions as DiscoverOptions,
    DiscoveryRecord as DiscoveryRecord,
    DiscoveryStep as DiscoveryStep,
    calibrate_baseline as calibrate_baseline,
    discover as discover,
)
from ._pipeline import PipelineData as PipelineData, pipeline_signals as pipeline_signals
from ._refit import refit_structure as refit_structure, residual_spectra as residual_spectra
from ._report import report_dict as report_dict, write_report as write_report
from ._select import cv_gain as cv_gain, fold_basis as fold_basis, sindy_select as sindy_select
from ._spectrum import (
    OrderSpectrum as OrderSpectrum,
    order_spectrum as order_spectrum,
    spectrum_peaks as spectrum_peaks,
)
from ._start import (
    calibrate_start as calibrate_start,
    calibrate_structure as calibrate_structure,
    fallback_tables as fallback_tables,
)

# the API page's order: the loop and its results first, then its parts
__all__ = [
    "discover",
    "DiscoverOptions",
    "DiscoveryRecord",
    "DiscoveryStep",
    "refit_structure",
    "write_report",
    "report_dict",
    "calibrate_baseline",
    "calibrate_start",
    "calibrate_structure",
    "fallback_tables",
    "residual_spectra",
    "OrderSpectrum",
    "order_spectrum",
    "spectrum_peaks",
    "LibraryOptions",
    "FAMILIES",
    "Candidate",
    "build_library",
    "cv_gain",
    "fold_basis",
    "sindy_select",
    "PipelineData",
    "pipeline_signals",
    "check_inputs",
    "apparent_ratio",
]
