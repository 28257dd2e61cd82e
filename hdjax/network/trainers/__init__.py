"""Trainers for the network: the paper's per-sample back-propagation and a jitted optax loop."""

from ._backprop import backprop_step as backprop_step, train_backprop as train_backprop
from ._optax import train_optax as train_optax
