"""What `hdjax.effects` lends to the other hdjax packages: the Dahl state carried across chunks,
the helpers of the plant's effects, and terms split for compiled programs.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._base import check_slot as check_slot, coupled as coupled
from ._dahl_carry import (
    DahlCarry as DahlCarry,
    is_sequential as is_sequential,
)
from ._fields import concrete as concrete
from ._hysteresis import after_play as after_play
from ._skew import BACK_SAMPLES as BACK_SAMPLES
from ._traced import (
    join_hypers as join_hypers,
    opaque as opaque,
    run_split as run_split,
    split_hypers as split_hypers,
    with_fields as with_fields,
)
