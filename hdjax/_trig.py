r"""Sine and cosine that XLA vectorises: Cody-Waite reduction and fdlibm's kernels, in JAX ops.

On CPU, XLA lowers a float64 `jnp.sin` over an array to one libm call per element (about 10 ns
each, measured on the 2-core benchmark machine), while `tanh` and polynomials are vectorised
(1-2 ns) and fuse into the surrounding loop. The plant evaluates the kinematic-error harmonics
(Song et al. eq. (9)) of the motor and link angles at every RK4 stage, and the compliance model's
kinematic terms (eq. (9)) need sines of every sample's angle, so both use these.

[`sincos`][], [`sin`][] and [`cos`][] compute the same functions from elementwise operations only:

1. $n = \operatorname{round}(2x/\pi)$ and $r = x - n\pi/2$, with $\pi/2$ split into three 23-bit
   parts and a remainder so that every product $n c_j$ is exact for $|n| < 2^{30}$ (Cody and
   Waite, 1980);
2. the fdlibm minimax polynomials `__kernel_sin` and `__kernel_cos` on $|r| \le \pi/4$;
3. the quadrant $n \bmod 4$ picks $\pm\sin r$ or $\pm\cos r$.

The error is within about 2 ulp of the correctly rounded value for $|x| < 10^9$ rad (tested
against NumPy's libm); beyond that the reduction loses accuracy, far outside any joint angle
(10^9 rad of motor angle is 1.6e8 revolutions). Derivatives are exact by construction
(`custom_jvp`: $\sin' = \cos$, $\cos' = -\sin$).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

_INV_PIO2 = 0.6366197723675814
# pi/2 = C1 + C2 + C3 + C4, C1..C3 with 23 significant bits (n * Cj exact for |n| < 2**30)
_C1 = 1.570796251296997
_C2 = 7.549789415861596e-08
_C3 = 5.390302529957765e-15
_C4 = 3.2820035428735005e-22

# fdlibm k_sin.c / k_cos.c
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)


def _reduce(x):
    n = jnp.round(x * _INV_PIO2)
    r = (((x - n * _C1) - n * _C2) - n * _C3) - n * _C4
    return n, r


def _kernels(r):
    z = r * r
    ps = _S[5]
    for c in _S[4::-1]:
        ps = ps * z + c
    pc = _C[5]
    for c in _C[4::-1]:
        pc = pc * z + c
    s = r + r * z * ps
    # fdlibm's cos kernel: 1 - z/2 + z^2 P(z), with the 1 - z/2 part compensated
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * z * pc)
    return s, c


def sincos(x):
    r"""$(\sin x, \cos x)$ from elementwise operations only, sharing one reduction (see the module).

    Within about 2 ulp of libm for $|x| < 10^9$. Not differentiable through `custom_jvp` (use
    [`sin`][] and [`cos`][] under `jax.grad`; plain autodiff of this function is correct too, up
    to the polynomial's derivative error of about 1e-15).
    """
    n, r = _reduce(x)
    s, c = _kernels(r)
    q = n - 4.0 * jnp.floor(n * 0.25)  # n mod 4, exact in float64
    sin = jnp.where(q == 0.0, s, jnp.where(q == 1.0, c, jnp.where(q == 2.0, -s, -c)))
    cos = jnp.where(q == 0.0, c, jnp.where(q == 1.0, -s, jnp.where(q == 2.0, -c, s)))
    return sin, cos


@jax.custom_jvp
def sin(x):
    r"""$\sin x$ from elementwise operations only (vectorised by XLA on CPU); see the module.

    Within about 2 ulp of libm for $|x| < 10^9$. Used for the kinematic-error harmonics of Song
    et al. eq. (9).
    """
    return sincos(x)[0]


def harmonic_sum(orders, amplitudes, phases, angle):
    r"""$\sum_j a_j \sin(K_j \theta + \varphi_j)$: Song et al. eq. (9).

    A Python sum over the static number of harmonics, which keeps XLA from a reduction; zeros
    shaped like `angle` when there are none. Shared by the kinematic error and the compliance
    ripple.
    """
    terms = [amplitudes[j] * sin(orders[j] * angle + phases[j]) for j in range(orders.shape[0])]
    return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(angle)


@jax.custom_jvp
def cos(x):
    r"""$\cos x$ from elementwise operations only (vectorised by XLA on CPU); see the module."""
    return sincos(x)[1]


@sin.defjvp
def _sin_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    s, c = sincos(x)
    return s, c * t


@cos.defjvp
def _cos_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    s, c = sincos(x)
    return c, -s * t
