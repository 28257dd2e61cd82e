"""What `hdjax.network` lends to the other hdjax packages: the network's input features.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._estimate import network_features as network_features
