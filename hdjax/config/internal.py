"""What `hdjax.config` lends to the other hdjax packages: path resolution and the schema's
structure keys.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._load import resolve_path as resolve_path
from ._schema import (
    STRUCTURE_KEYS as STRUCTURE_KEYS,
    joint_of as joint_of,
    structure_settings as structure_settings,
)
