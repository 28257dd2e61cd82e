r"""The flexspline strain-gauge torque sensor: Hashimoto, Kiyosawa & Paul (1993), eqs. (1)-(13).

Four active gauges on the radial diaphragm of the flexspline, two at $\pm 45°$ (R1, R2) and two
more a quarter turn away (R3, R4), form a Wheatstone bridge. The torsional strain $\epsilon_t$ is
read by every gauge with alternating sign; the elliptical wave generator adds a modulation
$\Psi_0 \sin 2\beta$ that the quarter-turn pair cancels (eqs. (3)-(5)). A circumferential gauge
misalignment $\Delta\alpha$ leaves a residual ripple of amplitude $2\Psi_0|\sin\Delta\alpha|$
(eqs. (9)-(13)).

**References:**

M. Hashimoto, Y. Kiyosawa, R. P. Paul, "A torque sensing technique for robots with harmonic
drives", IEEE Trans. Robotics and Automation 9(1), 1993, pp. 108-116.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Float, RealLike, Scalar
from .._errors import ConfigError

# Paper values (Section III-A/B).
PSI0_PAPER = 100e-6
"""Wave-generator modulation amplitude $\\Psi_0$ [strain], the same for all sizes (Sec. III-A)."""
EPS_RATED_PAPER = 200e-6
"""Torsional strain at rated torque $\\epsilon_t^R$ [strain], 'about 200 µstrain' (Sec. III-A)."""


def _check_nonnegative_number(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    if not math.isfinite(value) or value < 0:
        raise ConfigError(f"{name} must be a non-negative finite number, got {value!r}")


def _check_positive_number(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return  # arrays and tracers are checked by the caller or not at all
    if not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{name} must be a positive finite number, got {value!r}")


class FlexsplineGeometry(eqx.Module):
    r"""Radial diaphragm of a flexspline, modelled as an annular disk (Appendix, Fig. 18).

    **Arguments:**

    - `thickness`: diaphragm thickness $t$ [m]; the paper's 49 mm flexspline has 0.39 mm.
    - `r1`: radius of the fixed (inner, boss) edge $r_1$ [m]; paper: 15.8 mm.
    - `r2`: outer radius of the diaphragm $r_2$ [m]; paper: 24.85 mm. Must exceed `r1`.
    - `shear_modulus`: $G$ [N/m²]; $8.3\times10^{10}$ for the Ni-Cr-Mo steel of flexsplines.

    Raises [`hdjax.ConfigError`][] for a non-positive thickness, radius or modulus, or for
    $r_1 \ge r_2$ (no diaphragm between the boss and the cup).
    """

    thickness: Scalar = 0.39e-3
    r1: Scalar = 15.8e-3
    r2: Scalar = 24.85e-3
    shear_modulus: Scalar = 8.3e10

    def __check_init__(self):
        _check_positive_number("FlexsplineGeometry.thickness", self.thickness)
        _check_positive_number("FlexsplineGeometry.r1", self.r1)
        _check_positive_number("FlexsplineGeometry.r2", self.r2)
        _check_positive_number("FlexsplineGeometry.shear_modulus", self.shear_modulus)
        if isinstance(self.r1, (int, float)) and isinstance(self.r2, (int, float)):
            if self.r1 >= self.r2:
                raise ConfigError(
                    f"non-physical flexspline geometry: inner radius r1={self.r1!r} m must be "
                    f"smaller than the diaphragm radius r2={self.r2!r} m (the paper's 49 mm "
                    "flexspline has r1=15.8e-3, r2=24.85e-3)"
                )


def strain_per_torque(geometry: FlexsplineGeometry) -> Float[Array, ""]:
    r"""Gauge strain per unit torque $\epsilon_t / T$ on the radial part, eq. (7).

    $$\frac{\epsilon_t}{T} = \frac{r_1 + r_2}{8\pi t G r_1^2 r_2}.$$

    The Appendix derives this from the disk model, eqs. (A1)-(A6). Written out, eq. (A6) reads
    $\frac{1}{8\pi t G}(r_1^{-2} - r_2^{-2})\frac{r_2}{r_1 - r_2}$, which simplifies to
    **minus** eq. (7): the two have the same magnitude, the sign flip coming from the factor
    $r_2/(r_1 - r_2)$ of eq. (A5), whose denominator is negative for $r_1 < r_2$. Both give the
    paper's $K_R \approx 50$ µV/(N·m), eq. (14) (see
    [`hdjax.strain.strain_per_torque_appendix`][], checked in the tests); this function uses
    eq. (7), positive for positive torque.

    **Returns:** $\epsilon_t/T$ [strain/(N·m)].
    """
    g = geometry
    r1 = jnp.asarray(g.r1, jnp.float64)
    r2 = jnp.asarray(g.r2, jnp.float64)
    return (r1 + r2) / (8.0 * jnp.pi * g.thickness * g.shear_modulus * r1**2 * r2)


def strain_per_torque_appendix(geometry: FlexsplineGeometry) -> Float[Array, ""]:
    r"""Gauge strain per unit torque as written in the Appendix, eq. (A6), sign included.

    $$\frac{\epsilon_t}{T} = \frac{1}{8\pi t G}\left(\frac{1}{r_1^2} -
    \frac{1}{r_2^2}\right)\frac{r_2}{r_1 - r_2} = -\frac{r_1 + r_2}{8\pi t G r_1^2 r_2}.$$

    Kept separately so that the algebra linking (A6) to eq. (7) is tested, not assumed: it is
    the negative of [`hdjax.strain.strain_per_torque`][] (eq. (7)).
    """
    g = geometry
    r1 = jnp.asarray(g.r1, jnp.float64)
    r2 = jnp.asarray(g.r2, jnp.float64)
    theta_d_per_torque = (1.0 / r1**2 - 1.0 / r2**2) / (
        4.0 * jnp.pi * g.thickness * g.shear_modulus
    )
    alpha_d_per_torque = r2 / (r1 - r2) * theta_d_per_torque  # eq. (A5), as printed
    return alpha_d_per_torque / 2.0  # eq. (A6)


def torsional_strain(geometry: FlexsplineGeometry, torque: RealLike) -> Float[Array, " ..."]:
    r"""Torsional gauge strain $\epsilon_t$ under a torque $T$ [N·m], eq. (7)."""
    return jnp.asarray(torque, jnp.float64) * strain_per_torque(geometry)


def resolved_torque_gain(
    geometry: FlexsplineGeometry, gauge_factor: Scalar = 2.1, supply: Scalar = 3.0
) -> Float[Array, ""]:
    r"""Resolved torque gain (voltage resolution) of the bridge, eq. (8).

    $$K_R = \frac{E_\text{output}}{T} = \frac{K_{gf} E_\text{supply}(r_1 + r_2)}{8\pi t G r_1^2
    r_2}.$$

    With the paper's values ($t$ = 0.39 mm, $r_1$ = 15.8 mm, $r_2$ = 24.85 mm,
    $G = 8.3\times10^{10}$ N/m², $K_{gf}$ = 2.1, 3 V) this is 50.7 µV/(N·m), the paper's
    "$K_R$ = 50 µV/N·m" of eq. (14); after the ×500 amplifier, 25 mV/(N·m) (measured: 24).

    **Arguments:**

    - `geometry`: the diaphragm, [`hdjax.strain.FlexsplineGeometry`][].
    - `gauge_factor`: $K_{gf}$ (2.1 for the paper's Cu-Ni foil gauges).
    - `supply`: bridge excitation $E_\text{supply}$ [V].

    **Returns:** $K_R$ [V/(N·m)].
    """
    _check_positive_number("gauge_factor", gauge_factor)
    _check_positive_number("supply", supply)
    return gauge_factor * supply * strain_per_torque(geometry)


class GaugeStrains(NamedTuple):
    """Strains of the four active gauges R1-R4 (Fig. 9(a)), each shaped like the inputs."""

    e1: Float[Array, " ..."]
    e2: Float[Array, " ..."]
    e3: Float[Array, " ..."]
    e4: Float[Array, " ..."]


def gauge_strains(
    eps_t: RealLike,
    beta: RealLike,
    psi0: Scalar = PSI0_PAPER,
    dalpha: RealLike = 0.0,
    common: RealLike = 0.0,
) -> GaugeStrains:
    r"""Strains on the four gauges, eqs. (1)-(4) and (9).

    Gauges R1/R2 sit at angle $\beta$ from the ellipse's major axis, at $+45°$ and $-45°$ to the
    radius; R3/R4 sit a quarter turn further, displaced by the misalignment $\Delta\alpha$:

    $$\epsilon_1 = \epsilon_t + \epsilon_w,\quad \epsilon_2 = -\epsilon_t + \epsilon_{w'},\quad
    \epsilon_w - \epsilon_{w'} = \Psi_0\sin 2\beta \qquad \text{(eqs. (1)-(3))},$$

    and the same at $\beta - \pi/2 - \Delta\alpha$ for R3/R4 (eq. (9)). The paper only fixes the
    difference $\epsilon_w - \epsilon_{w'}$; here it is split antisymmetrically
    ($\epsilon_w = -\epsilon_{w'} = \tfrac12\Psi_0\sin 2\beta$) and a strain `common` to all four
    gauges (thermal expansion, membrane strain) can be added: the bridge cancels it (eq. (5) and
    "temperature compensation is performed at the same time").

    **Arguments:**

    - `eps_t`: torsional strain $\epsilon_t$ (eq. (7)).
    - `beta`: angle $\beta$ of gauges R1/R2 from the major axis of the wave generator [rad].
    - `psi0`: modulation amplitude $\Psi_0$ of $\epsilon_1 - \epsilon_2$ [strain].
    - `dalpha`: circumferential misalignment $\Delta\alpha$ of R3/R4 [rad].
    - `common`: strain common to all gauges.

    **Returns:** a [`hdjax.strain.GaugeStrains`][] (e1, e2, e3, e4).
    """
    eps_t = jnp.asarray(eps_t, jnp.float64)
    beta = jnp.asarray(beta, jnp.float64)
    dalpha = jnp.asarray(dalpha, jnp.float64)
    common = jnp.asarray(common, jnp.float64)
    w12 = 0.5 * psi0 * jnp.sin(2.0 * beta)
    w34 = 0.5 * psi0 * jnp.sin(2.0 * (beta - 0.5 * jnp.pi - dalpha))
    return GaugeStrains(
        e1=eps_t + w12 + common,
        e2=-eps_t - w12 + common,
        e3=eps_t + w34 + common,
        e4=-eps_t - w34 + common,
    )


def bridge_output(
    strains: GaugeStrains,
    gauge_factor: Scalar = 2.1,
    supply: Scalar = 3.0,
    *,
    linear: bool = True,
) -> Float[Array, " ..."]:
    r"""Output voltage of the four-active-gauge Wheatstone bridge, eq. (5).

    Linear (the paper's eq. (5)):
    $E_\text{output} = \tfrac{K_{gf}}{4}(\epsilon_1 + \epsilon_3 - \epsilon_2 - \epsilon_4)
    E_\text{supply}$. With `linear=False` the exact bridge of Fig. 9(b) is evaluated,
    $E_\text{supply}\,[R_1/(R_1+R_2) - R_4/(R_3+R_4)]$ with $R_i = R_0(1 + K_{gf}\epsilon_i)$,
    whose departure from eq. (5) is of order $K_{gf}\epsilon$ (a few 1e-4 relative).

    **Returns:** the bridge voltage [V] (before the amplifier).
    """
    e1, e2, e3, e4 = strains
    if linear:
        return 0.25 * gauge_factor * (e1 + e3 - e2 - e4) * supply
    r1, r2, r3, r4 = (1.0 + gauge_factor * e for e in (e1, e2, e3, e4))
    return supply * (r1 / (r1 + r2) - r4 / (r3 + r4))


class Ripple(NamedTuple):
    """Residual modulation $\\Psi\\sin(2\\beta + \\gamma)$ of the bridge sum, eqs. (10)-(12)."""

    amplitude: Float[Array, " ..."]
    """$\\Psi = 2\\Psi_0|\\sin\\Delta\\alpha|$ [strain], eq. (12)."""
    phase: Float[Array, " ..."]
    """$\\gamma$ [rad], eq. (11)."""


def residual_ripple(dalpha: RealLike, psi0: Scalar = PSI0_PAPER) -> Ripple:
    r"""Residual ripple left by a gauge misalignment $\Delta\alpha$, eqs. (10)-(12).

    $$\epsilon_1 + \epsilon_3 - \epsilon_2 - \epsilon_4 = 4\epsilon_t + \Psi\sin(2\beta+\gamma),
    \quad \gamma = \tan^{-1}\frac{\sin 2\Delta\alpha}{1 - \cos 2\Delta\alpha},\quad
    \Psi = 2\Psi_0|\sin\Delta\alpha|.$$

    The principal-value arctangent of eq. (11) is the right branch: it equals
    $\pi/2 - \Delta\alpha$ for $0 < \Delta\alpha < \pi$ and $-\pi/2 - \Delta\alpha$ for
    $-\pi < \Delta\alpha < 0$, which together with the absolute value in eq. (12) reproduces
    $\Psi_0[\sin 2\beta - \sin 2(\beta - \Delta\alpha)]$ exactly (tested against the sum of the
    four gauge strains). At $\Delta\alpha = 0$ the phase is undefined and set to 0 (the
    amplitude is 0).
    """
    dalpha = jnp.asarray(dalpha, jnp.float64)
    s2 = jnp.sin(2.0 * dalpha)
    c2 = 1.0 - jnp.cos(2.0 * dalpha)
    safe_c2 = jnp.where(c2 == 0.0, 1.0, c2)
    gamma = jnp.where(c2 == 0.0, 0.0, jnp.arctan(s2 / safe_c2))
    return Ripple(amplitude=2.0 * psi0 * jnp.abs(jnp.sin(dalpha)), phase=gamma)


def misalignment_error_index(
    dalpha: RealLike, psi0: Scalar = PSI0_PAPER, eps_rated: Scalar = EPS_RATED_PAPER
) -> Float[Array, " ..."]:
    r"""Sensing inaccuracy index $E_R$ from a gauge misalignment, eq. (13).

    $$E_R = \frac{\Psi}{4\epsilon_t^R} = \frac{\Psi_0|\sin\Delta\alpha|}{2\epsilon_t^R},$$

    the ripple amplitude as a fraction of the rated-torque reading. With the paper's
    $\Psi_0$ = 100 µstrain and $\epsilon_t^R$ = 200 µstrain, $E_R = 0.25|\sin\Delta\alpha|$,
    0.87% of rated torque at $|\Delta\alpha| = 2°$ ("approximately within ±1%").

    **Arguments:**

    - `dalpha`: misalignment $\Delta\alpha$ [rad].
    - `psi0`: modulation amplitude $\Psi_0$ [strain].
    - `eps_rated`: torsional strain at rated torque $\epsilon_t^R$ [strain].

    **Returns:** $E_R$ as a fraction (multiply by 100 for %).
    """
    _check_nonnegative_number("psi0", psi0)
    _check_positive_number("eps_rated", eps_rated)
    return residual_ripple(dalpha, psi0).amplitude / (4.0 * eps_rated)
