"""What `hdjax.report` lends to the other hdjax packages: the figure rules the command line prints.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._figures import KNEE_RULE as KNEE_RULE
