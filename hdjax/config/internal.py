"""What `hdjax.config` lends to the other hdjax packages: path resolution, the schema's structure
keys and the saved model's checks.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._load import resolve_path as resolve_path
from ._preflight import check_angles as check_angles
from ._saved_model import (
    angle_ratio_mismatch as angle_ratio_mismatch,
    ratio_mismatch as ratio_mismatch,
)
from ._schema import (
    STRUCTURE_KEYS as STRUCTURE_KEYS,
    model_of as model_of,
    paper_model as paper_model,
)
from ._streamed import PartStream as PartStream
