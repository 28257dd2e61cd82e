"""What `hdjax.modelfile` lends to the other hdjax packages: the angle-ratio checks.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._saved_model import (
    angle_ratio_mismatch as angle_ratio_mismatch,
    ratio_mismatch as ratio_mismatch,
)
