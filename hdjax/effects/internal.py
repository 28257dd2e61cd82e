"""What `hdjax.effects` lends to the other hdjax packages: the Dahl state carried across chunks and
the helpers of the plant's effects.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._base import check_slot as check_slot
from ._dahl_carry import (
    DahlCarry as DahlCarry,
    is_sequential as is_sequential,
)
from ._fields import concrete as concrete
from ._skew import BACK_SAMPLES as BACK_SAMPLES
