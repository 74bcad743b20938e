"""The compiled covariance of corrected flow samples (the maths is in the docstring of
:mod:`wind_comp.flow_uncertainty`).

Compiled (numba, cached on disk) and written out element by element: the live node corrects
one sample per message, and numpy's cost per call on 3×3 arrays (dozens of calls a sample) made
the covariance a third of the cost of correcting it. One loop over the samples serves a
batch of one (live) and of many (offline) with the same arithmetic in the same order, so each
sample's covariance does not depend on its batch.

The arithmetic is that of the formula written with numpy, operation for operation, so that both
give the same figures to the bit: a 3×3 matrix product (numpy's ``@``, which calls
OpenBLAS) as a chain of fused multiply-adds over k = 0, 1, 2, as OpenBLAS's kernels compute it
on processors with FMA (LLVM's ``llvm.fma``, exact on any processor); a matrix times a vector
(numpy's ``einsum``) as (p₀ + p₂) + p₁ of its three products, rounded one by one.
"""

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

TRACE_FLOOR = 1e-300
"""Below this a term's trace counts as zero (it gets no weight and adds nothing)."""


@intrinsic
def _llvm_fma(typing_context, a, b, c):
    """a·b + c rounded once (LLVM's ``llvm.fma.f64``)."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, arguments):
        double = ir.DoubleType()
        function_type = ir.FunctionType(double, [double, double, double])
        fma = builder.module.declare_intrinsic("llvm.fma", [double], function_type)
        return builder.call(fma, arguments)

    return signature, codegen


if numba.config.DISABLE_JIT:
    # Interpreted (NUMBA_DISABLE_JIT, to check the compiled code against its source): Python
    # before 3.13 has no fused multiply-add; the product is then rounded on its own.
    def _fused_multiply_add(a, b, c):
        return a * b + c

else:
    _fused_multiply_add = _llvm_fma


@numba.njit(cache=True)
def _dot(a0, a1, a2, b0, b1, b2):
    """a·b of 3-vectors as a chain of fused multiply-adds (an element of numpy's ``@``)."""
    return _fused_multiply_add(a2, b2, _fused_multiply_add(a1, b1, a0 * b0))


@numba.njit(cache=True)
def _product(a, b, out):
    """out = a·b of 3×3 matrices, as numpy's ``@``."""
    for i in range(3):
        for j in range(3):
            out[i, j] = _dot(a[i, 0], a[i, 1], a[i, 2], b[0, j], b[1, j], b[2, j])


@numba.njit(cache=True)
def _sandwich(jacobian, covariance, scratch, out):
    """out = (J·P)·Jᵀ of 3×3 matrices, as numpy's ``@`` (``scratch`` holds J·P)."""
    _product(jacobian, covariance, scratch)
    for i in range(3):
        for j in range(3):
            out[i, j] = _dot(
                scratch[i, 0],
                scratch[i, 1],
                scratch[i, 2],
                jacobian[j, 0],
                jacobian[j, 1],
                jacobian[j, 2],
            )


@numba.njit(cache=True)
def _rotated(matrix, x, y, z, out):
    """out = M·v of a 3×3 matrix and v = (x, y, z), as numpy's ``einsum``."""
    for i in range(3):
        out[i] = (matrix[i, 0] * x + matrix[i, 2] * z) + matrix[i, 1] * y


@numba.njit(cache=True)
def _skew(x, y, z, out):
    """out = [v×] of v = (x, y, z), so that [v×]·u = v × u."""
    out[0, 0], out[0, 1], out[0, 2] = 0.0, -z, y
    out[1, 0], out[1, 1], out[1, 2] = z, 0.0, -x
    out[2, 0], out[2, 1], out[2, 2] = -y, x, 0.0


@numba.njit(cache=True)
def _root_of_trace(a):
    """√tr(A), 0 for a negative trace."""
    return np.sqrt(max(a[0, 0] + a[1, 1] + a[2, 2], 0.0))


@numba.njit(cache=True)
def _weight(root, total_root):
    """1 / w_i of a term with √tr = ``root`` (w_i = root / Σ√tr); 0 for a term of no trace."""
    return total_root / max(root, TRACE_FLOOR) if root > TRACE_FLOOR else 0.0


@numba.njit(cache=True)
def sample_covariance(
    rotation,
    mounting_bs,
    lever_arm_body_m,
    flow_sensor_mps,
    rate_body_rad_s,
    attitude_covariance_enu_rad2,
    velocity_covariance_enu_m2s2,
    rate_covariance_body_rad2s2,
    noise_covariance_m2s2,
    scratch,
    navigation_out,
    sensor_out,
):
    """The navigation's and the sensor noise's parts of one corrected sample's ENU covariance
    (m²/s²), into the 3×3 ``navigation_out`` and ``sensor_out``: R_nb (3×3) and the arguments of
    :func:`wind_comp.flow_uncertainty.corrected_flow_covariance_enu` for one sample; ``scratch``
    a (6, 3, 3) work array."""
    skew, jacobian, product = scratch[0], scratch[1], scratch[2]
    attitude_term, rate_term = scratch[3], scratch[4]
    flow_body, lever_velocity, relative_enu = scratch[5, 0], scratch[5, 1], scratch[5, 2]
    bx, by, bz = lever_arm_body_m[0], lever_arm_body_m[1], lever_arm_body_m[2]
    flow, rate = flow_sensor_mps, rate_body_rad_s
    # a = R_nb·(R_bw·V_w + ω × B), the fluid's velocity relative to the sensor, ENU.
    _rotated(mounting_bs, flow[0], flow[1], flow[2], flow_body)
    _skew(rate[0], rate[1], rate[2], skew)
    _rotated(skew, bx, by, bz, lever_velocity)
    _rotated(
        rotation,
        flow_body[0] + lever_velocity[0],
        flow_body[1] + lever_velocity[1],
        flow_body[2] + lever_velocity[2],
        relative_enu,
    )
    _skew(relative_enu[0], relative_enu[1], relative_enu[2], skew)
    _sandwich(skew, attitude_covariance_enu_rad2, product, attitude_term)
    _skew(bx, by, bz, skew)
    _product(rotation, skew, jacobian)
    _sandwich(jacobian, rate_covariance_body_rad2s2, product, rate_term)
    velocity_term = velocity_covariance_enu_m2s2
    root_attitude = _root_of_trace(attitude_term)
    root_velocity = _root_of_trace(velocity_term)
    root_rate = _root_of_trace(rate_term)
    total_root = root_attitude + root_velocity + root_rate
    scale_attitude = _weight(root_attitude, total_root)
    scale_velocity = _weight(root_velocity, total_root)
    scale_rate = _weight(root_rate, total_root)
    for i in range(3):
        for j in range(3):
            navigation_out[i, j] = (
                attitude_term[i, j] * scale_attitude
                + velocity_term[i, j] * scale_velocity
                + rate_term[i, j] * scale_rate
            )
    _product(rotation, mounting_bs, jacobian)
    _sandwich(jacobian, noise_covariance_m2s2, product, sensor_out)


@numba.njit(cache=True)
def flow_covariances_enu(
    rotations_nb,
    mounting_bs,
    lever_arm_body_m,
    flows_sensor_mps,
    rates_body_rad_s,
    attitude_covariances_enu_rad2,
    velocity_covariances_enu_m2s2,
    rate_covariances_body_rad2s2,
    noise_covariances_m2s2,
    navigation_out,
    sensor_out,
):
    """:func:`sample_covariance` of N samples, into ``navigation_out`` and ``sensor_out``
    (N, 3, 3): every per-sample argument with N rows (the noise too)."""
    scratch = np.empty((6, 3, 3))
    for n in range(rotations_nb.shape[0]):
        sample_covariance(
            rotations_nb[n],
            mounting_bs,
            lever_arm_body_m,
            flows_sensor_mps[n],
            rates_body_rad_s[n],
            attitude_covariances_enu_rad2[n],
            velocity_covariances_enu_m2s2[n],
            rate_covariances_body_rad2s2[n],
            noise_covariances_m2s2[n],
            scratch,
            navigation_out[n],
            sensor_out[n],
        )
