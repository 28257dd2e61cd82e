r"""What an effect term's C code is made of, for the estimator `hdjax export` writes.

The exported estimator computes one sample at a time (a controller's step), so each regression
term ([`hdjax.effects.AbstractTerm`][]) states its columns as C expressions of the present
sample's signals, beside its JAX and NumPy columns, in its own family's module. A term opts in
by defining the method `c_code(c) -> CSnippet`, with `c` the exporter's
[`hdjax.effects.AbstractCEmitter`][] (the names and literals of the generated code); a term
without it has `c_code = None` and is refused by the exporter with one line naming it.

What the snippet holds depends on the term's `torque_kind`:

- `"none"`: `columns`, one C expression per column ($\psi_j$);
- `"linear"`: `columns`, one C expression of the torque slope $u_j$ per column
  ($\psi_j = u_j T$);
- `"memoryless"`: `value` $f(T)$ and `slope` $f'(T)$, of the torque `c.torque` (the slope may
  read the value as `c.value`);
- `"path"`: `path_scale`, the torque scale $T_h$ of its Dahl state, which the exporter's
  implicit per-sample step drives (Song et al. Fig. 2; see `hdjax.compliance`).

Any kind may carry memory (`state`: members of the estimator's state struct with their initial
values, read and written through `c.state(name)`; `double_state` for members that hold time
stamps or angles, double at either precision), statements run once per sample before any
column is evaluated (`update`; a term that changes the signals themselves, such as a delay
between the two encoders, assigns them here), statements run where its columns are evaluated
(`lines`, declaring locals named by `c.local(name)`), and static helper functions (`helpers`).
The generated code offers `hdjax_clip(x, lo, hi)` and `hdjax_sign(x)` (as `jnp.clip` and
`jnp.sign`, of type `real`) to every snippet.
A term whose estimate would read samples after the present one says why in `noncausal`; the
exporter refuses it with that reason.
"""

from __future__ import annotations

import abc
import dataclasses


@dataclasses.dataclass(frozen=True)
class CSnippet:
    """The C code of one term group (see the module docstring for what each kind fills in).

    **Fields:** `columns` (C expressions), `value`, `slope` (memoryless terms), `path_scale`
    (path terms), `state` (`(name, initial value)` pairs, of type `real`), `double_state` (the
    same, always double: past time stamps and angles), `update`, `lines` and `helpers` (C
    source lines), `noncausal` (why the term cannot be computed causally, or `None`).
    """

    columns: tuple[str, ...] = ()
    value: str | None = None
    slope: str | None = None
    path_scale: float | None = None
    state: tuple[tuple[str, float], ...] = ()
    double_state: tuple[tuple[str, float], ...] = ()
    update: tuple[str, ...] = ()
    lines: tuple[str, ...] = ()
    helpers: tuple[str, ...] = ()
    noncausal: str | None = None


class AbstractCEmitter(abc.ABC):
    """The names and literals a term's `c_code` writes its C code with.

    The exporter implements it for one term at a time (its state members and locals get a
    prefix of their own) and one precision: `real` is the type of the model's arithmetic
    (`double`, or `float` for `--precision single`); angles, time stamps and the twist are
    double in either.

    **Attributes:** `real` (the C type name), `torque` (memoryless terms: the C variable of
    the torque $T$), `value` (memoryless terms: the variable holding `value`, for `slope`),
    `first` (a C expression, true at the first sample after `hdjax_init`).
    """

    real: str
    torque: str
    value: str
    first: str

    @abc.abstractmethod
    def num(self, x: float) -> str:
        """A literal of type `real` for the number `x`."""

    @abc.abstractmethod
    def dnum(self, x: float) -> str:
        """A double literal for `x` (for arguments computed in double, such as angles)."""

    @abc.abstractmethod
    def signal(self, name: str) -> str:
        """The present sample's signal `name` (`twist`, `current`, `theta_m`, `theta_l`,
        `omega_m`, `omega_l` or an extra column) as a `real` expression."""

    @abc.abstractmethod
    def angle(self, name: str) -> str:
        """The signal `name` as a double expression (arguments of harmonics: a motor angle of
        hundreds of radians needs double before the reduction)."""

    @abc.abstractmethod
    def state(self, name: str) -> str:
        """The lvalue of this term's state member `name` (declared in `CSnippet.state`)."""

    @abc.abstractmethod
    def local(self, name: str) -> str:
        """A local variable name of this term's own, for `lines` and `update`."""

    @abc.abstractmethod
    def time(self) -> str:
        """The present sample's time stamp [s] as a double expression."""

    @abc.abstractmethod
    def fn(self, name: str) -> str:
        """The C99 `<math.h>` function `name` (`tanh`, `exp`, ...) at the precision `real`."""

    @abc.abstractmethod
    def sincos(self, arg: str, sin: str, cos: str) -> str:
        """A statement declaring `real` locals `sin` and `cos` = $\\sin, \\cos$ of the double
        expression `arg`, computed as hdjax's own sine and cosine (Cody-Waite
        reduction and fdlibm kernels, so the C code matches the JAX estimate to the ulp)."""
