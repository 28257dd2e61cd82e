"""A calibrated model as dependency-free C code with a causal per-sample step (`hdjax export`).

- [`hdjax.export.compliance_c`][]: the compliance model of Song et al. (2019), eqs. (26)-(27),
  with every effect term that has C code (each family's in its own module of
  [`hdjax.effects`][], see [`hdjax.effects.CSnippet`][]).
- [`hdjax.export.network_c`][]: the back-propagation network with its Kalman-filtered
  current, eqs. (29)-(41).
- [`hdjax.export.counts_c`][]: `hdjax_sample_from_counts`, a sample's angles from 64-bit
  encoder counts, converted exactly as hdjax reads a log's count columns.
- [`hdjax.export.export_files`][]: the files `hdjax export` writes (estimator, README, test
  vectors, check program) for a saved model.

The exported step computes each sample from that sample and earlier ones only, so it equals
[`hdjax.compliance.estimate_torque`][] (and [`hdjax.network.predict_torque`][]) with
`causal=True` to rounding.
"""

from ._assemble import FLAGS as FLAGS, CCode as CCode, StepParts as StepParts
from ._build import (
    CFLAGS as CFLAGS,
    CLibrary as CLibrary,
    CountsOffset as CountsOffset,
    build_library as build_library,
    compile_c as compile_c,
    find_compiler as find_compiler,
)
from ._causal import check_terms as check_terms, has_c_code as has_c_code
from ._compliance import compliance_c as compliance_c
from ._counts import (
    check_counts_per_rev as check_counts_per_rev,
    counts_c as counts_c,
    counts_per_rev as counts_per_rev,
    rad_per_count as rad_per_count,
)
from ._emitter import PRECISIONS as PRECISIONS, Emitter as Emitter, helpers as helpers
from ._files import (
    DOUBLE_TOLERANCE as DOUBLE_TOLERANCE,
    FILES as FILES,
    METHODS as METHODS,
    SINGLE_TOLERANCE as SINGLE_TOLERANCE,
    export_files as export_files,
)
from ._network import INPUT_SIGMAS as INPUT_SIGMAS, network_c as network_c
from ._vectors import expected as expected, synthetic_recording as synthetic_recording
