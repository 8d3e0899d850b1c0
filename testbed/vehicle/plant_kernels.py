"""The plant's compiled arithmetic: Fossen's equation of motion and its mapping onto pybullet.

Written once, compiled by numba and cached to disk beside this file (the first process on a
machine compiles in about a second; later ones load the machine code):

* :func:`fossen_acceleration`, the right-hand side of Fossen's equation (see
  :mod:`testbed.vehicle.hydrodynamics` for the model and :func:`~.hydrodynamics.body_acceleration`
  for its array interface), reading the model's coefficients as one float64 array laid out by
  :func:`~.hydrodynamics.coefficients` with the offsets below;
* :func:`pybullet_wrench` and :func:`pybullet_state`, what :class:`~.physics.Physics` computes
  from pybullet's reads each step (with :func:`matrix_from_quaternion`, pybullet's own
  rotation matrix, so a step calls pybullet only to read, apply and step): the body force and
  torque that give pybullet's rigid body Fossen's acceleration, and the state in NED/FRD.
  pybullet's world is NED rotated by π about north and its body frame FLU (vectors map by
  (x, −y, −z)); only this module and :mod:`.physics` (which makes the calls) know it.

They share one module because numba's disk cache does not follow calls into other files: a
cached kernel calling one defined elsewhere would keep a stale copy of it after that file
changed. numpy, numba and math only: no pybullet here.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]
Quat = tuple[float, float, float, float]

# Offsets into the coefficient array (one argument to unbox per call), filled by
# testbed.vehicle.hydrodynamics.coefficients.

MASS, WEIGHT, BUOYANCY = 0, 1, 2
COG, COB = 3, 6  # r_g, r_b (3 each)
INERTIA = 9  # I_o about CO, row-major (9)
ADDED = 18  # −diag(M_A): positive added masses (6)
CORIOLIS = 24  # the diagonal C_A(ν_r) is built from (6), see HydroModel.added_mass_coriolis
LINEAR, QUADRATIC = 30, 36  # Fossen's damping derivatives, ≤ 0 (6 each)
MASS_INVERSE = 42  # (M_RB + M_A)⁻¹, row-major (36)
N_COEFFICIENTS = 78

# Offsets into a plant's load array (what a step reads and writes besides pybullet's state, one
# argument to unbox per step), kept by testbed.vehicle.physics.Physics.

LOAD_WRENCH = 0  # the applied body wrench [N, N·m], FRD, about the CoG (6), held between writes
LOAD_CURRENT = 6  # the water velocity [m/s], NED (3)
LOAD_NU_DOT = 9  # written by each step: ν̇ at CO [m/s², rad/s²], FRD (6)
N_LOADS = 15


@numba.njit(cache=True)
def fossen_acceleration(
    c: FloatArray,
    nu: Vec6,
    down: Vec3,
    current_body: Vec3,
    scale: float,
    wrench: Vec6,
) -> Vec6:  # pragma: no cover - compiled (tests call it through numba)
    """ν̇ at CO from (M_RB + M_A)ν̇ = τ − C_RB(ν)ν − C_A(ν_r)ν_r − D(ν_r)ν_r − g(η) + M_A·ν̇_c.

    Fossen 2011: C_RB in its linear-velocity-independent form about CO (eq. 3.60), written
    out as m·ω×v_g and m·r_g×(ω×v) + ω×(I_o·ω); C_A(ν_r) of a diagonal added mass (eq. 6.43),
    −C_A·ν_r = [a₁×ω; a₁×v_r + a₂×ω] with a = diag(coriolis)·ν_r; D diagonal, linear plus
    quadratic; g(η) weight W at r_g and buoyancy B·scale at r_b along the world vertical. The
    current is constant in NED (irrotational), so its body derivative is ν̇_c = [v_c×ω; 0].

    Args:
        c: the model's :func:`coefficients`.
        nu: body velocity (u, v, w, p, q, r) at CO [m/s, rad/s], FRD.
        down: the world's down direction in the body, Rᵀ·(0, 0, 1) (unit), FRD.
        current_body: water velocity in the body [m/s], FRD.
        scale: submerged fraction of the hull, in [0, 1].
        wrench: applied body wrench (X, Y, Z, K, M, N) [N, N·m], FRD, moments about the CoG.

    Returns:
        (u̇, v̇, ẇ, ṗ, q̇, ṙ), body-frame derivatives of ν [m/s², rad/s²].
    """
    u, v, w, p, q, r = nu
    gx, gy, gz = down
    uc, vc, wc = current_body
    fx, fy, fz, mx, my, mz = wrench
    m = c[MASS]
    xg, yg, zg = c[COG], c[COG + 1], c[COG + 2]
    ur, vr, wr = u - uc, v - vc, w - wc
    # −C_RB(ν)ν: −m·ω×v_g (v_g = v + ω×r_g) and −m·r_g×(ω×v) − ω×(I_o·ω)
    ugx, ugy, ugz = u + q * zg - r * yg, v + r * xg - p * zg, w + p * yg - q * xg
    t0 = -m * (q * ugz - r * ugy)
    t1 = -m * (r * ugx - p * ugz)
    t2 = -m * (p * ugy - q * ugx)
    ox, oy, oz = q * w - r * v, r * u - p * w, p * v - q * u  # ω×v
    t3 = -m * (yg * oz - zg * oy)
    t4 = -m * (zg * ox - xg * oz)
    t5 = -m * (xg * oy - yg * ox)
    i = INERTIA
    hx = c[i] * p + c[i + 1] * q + c[i + 2] * r
    hy = c[i + 3] * p + c[i + 4] * q + c[i + 5] * r
    hz = c[i + 6] * p + c[i + 7] * q + c[i + 8] * r
    t3 -= q * hz - r * hy
    t4 -= r * hx - p * hz
    t5 -= p * hy - q * hx
    # −C_A(ν_r)ν_r = [a₁×ω; a₁×v_r + a₂×ω]
    k = CORIOLIS
    ax, ay, az = c[k] * ur, c[k + 1] * vr, c[k + 2] * wr
    bx, by, bz = c[k + 3] * p, c[k + 4] * q, c[k + 5] * r
    t0 += ay * r - az * q
    t1 += az * p - ax * r
    t2 += ax * q - ay * p
    t3 += ay * wr - az * vr + by * r - bz * q
    t4 += az * ur - ax * wr + bz * p - bx * r
    t5 += ax * vr - ay * ur + bx * q - by * p
    # −D(ν_r)ν_r (the derivatives are ≤ 0)
    lin, quad = LINEAR, QUADRATIC
    t0 += (c[lin] + c[quad] * abs(ur)) * ur
    t1 += (c[lin + 1] + c[quad + 1] * abs(vr)) * vr
    t2 += (c[lin + 2] + c[quad + 2] * abs(wr)) * wr
    t3 += (c[lin + 3] + c[quad + 3] * abs(p)) * p
    t4 += (c[lin + 4] + c[quad + 4] * abs(q)) * q
    t5 += (c[lin + 5] + c[quad + 5] * abs(r)) * r
    # −g(η) = [(W − B·s)·down; (W·r_g − B·s·r_b)×down]
    weight, buoyancy = c[WEIGHT], c[BUOYANCY] * scale
    net = weight - buoyancy
    t0 += net * gx
    t1 += net * gy
    t2 += net * gz
    lx = weight * xg - buoyancy * c[COB]
    ly = weight * yg - buoyancy * c[COB + 1]
    lz = weight * zg - buoyancy * c[COB + 2]
    t3 += ly * gz - lz * gy
    t4 += lz * gx - lx * gz
    t5 += lx * gy - ly * gx
    # τ about CO: the force, and the moment about the CoG plus r_g×F
    t0 += fx
    t1 += fy
    t2 += fz
    t3 += mx + yg * fz - zg * fy
    t4 += my + zg * fx - xg * fz
    t5 += mz + xg * fy - yg * fx
    # + M_A·ν̇_c, ν̇_c = [v_c×ω; 0]
    a = ADDED
    t0 += c[a] * (vc * r - wc * q)
    t1 += c[a + 1] * (wc * p - uc * r)
    t2 += c[a + 2] * (uc * q - vc * p)
    # ν̇ = M⁻¹·τ
    tau = (t0, t1, t2, t3, t4, t5)
    out = [0.0] * 6
    for row in range(6):
        total = 0.0
        for col in range(6):
            total += c[MASS_INVERSE + 6 * row + col] * tau[col]
        out[row] = total
    return (out[0], out[1], out[2], out[3], out[4], out[5])


@numba.njit(cache=True)
def matrix_from_quaternion(
    orientation: tuple[float, float, float, float],
) -> tuple[float, ...]:  # pragma: no cover - compiled
    """pybullet's ``getMatrixFromQuaternion``, computed here so a step makes no call for it:
    Bullet's ``btMatrix3x3::setRotation`` (s = 2/|q|², the same operations in the same order,
    so the same bits; checked against pybullet in the tests).

    Args:
        orientation: pybullet's quaternion (x, y, z, w), body FLU → world.

    Returns:
        R as its row-major 9 entries.
    """
    x, y, z, w = orientation
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return (
        1.0 - (yy + zz),
        xy - wz,
        xz + wy,
        xy + wz,
        1.0 - (xx + zz),
        yz - wx,
        xz - wy,
        yz + wx,
        1.0 - (xx + yy),
    )


@numba.njit(cache=True)
def body_velocity(
    rotation: tuple[float, ...], linear: Vec3, angular: Vec3
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """pybullet's world velocities in the body FRD: R_ned = diag(1, −1, −1)·R·diag(1, −1, −1),
    so body FLU velocities are Rᵀ·v and FRD is (x, −y, −z) of those.

    Args:
        rotation: pybullet's ``getMatrixFromQuaternion`` of the base orientation (row-major 9).
        linear: the CoG's velocity, pybullet's world [m/s].
        angular: angular velocity, pybullet's world [rad/s].

    Returns:
        (u_g, v_g, w_g, p, q, r): the CoG's velocity and the rates in the body FRD.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation
    vx, vy, vz = linear
    wx, wy, wz = angular
    return (
        r00 * vx + r10 * vy + r20 * vz,
        -(r01 * vx + r11 * vy + r21 * vz),
        -(r02 * vx + r12 * vy + r22 * vz),
        r00 * wx + r10 * wy + r20 * wz,
        -(r01 * wx + r11 * wy + r21 * wz),
        -(r02 * wx + r12 * wy + r22 * wz),
    )


@numba.njit(cache=True)
def pybullet_state(
    cog: Vec3,
    position: Vec3,
    orientation: tuple[float, float, float, float],
    linear: Vec3,
    angular: Vec3,
) -> tuple[Vec3, Quat, Vec6]:  # pragma: no cover - compiled (called by Physics)
    """(CO position NED, attitude quaternion wxyz body FRD → NED, ν at CO FRD) from pybullet's
    reads of the base (the CoG): position and orientation (x, y, z, w) and the world
    velocities. CO is at −r_g from the CoG: position = p_g − R_ned·r_g."""
    xg, yg, zg = cog
    px, py, pz = position
    ox, oy, oz, ow = orientation
    rotation = matrix_from_quaternion(orientation)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation
    # R_ned·r_g with R_ned = diag(1, −1, −1)·R·diag(1, −1, −1)
    north = px - (r00 * xg - r01 * yg - r02 * zg)
    east = -py - (-r10 * xg + r11 * yg + r12 * zg)
    down = -pz - (-r20 * xg + r21 * yg + r22 * zg)
    ug, vg, wg, p, q, r = body_velocity(rotation, linear, angular)
    nu = (ug - (q * zg - r * yg), vg - (r * xg - p * zg), wg - (p * yg - q * xg), p, q, r)
    return (north, east, down), (ow, ox, -oy, -oz), nu


@numba.njit(cache=True)
def pybullet_wrench(
    fossen: FloatArray,
    rigid: FloatArray,
    loads: FloatArray,
    height: float,
    orientation: tuple[float, float, float, float],
    velocity: tuple[Vec3, Vec3],
) -> tuple[Vec3, Vec3]:  # pragma: no cover - compiled (called by Physics)
    """The body force and torque that give pybullet's rigid body Fossen's acceleration.

    From pybullet's state (the CoG's height z-up, its orientation, the CoG's world velocity and
    the world angular velocity), the body velocity at CO, the
    down direction and the current in the body FRD and the submerged fraction go to
    :func:`fossen_acceleration`; its ν̇ becomes the force
    m·(v̇_o + ω̇×r_g + ω×v_g) and the torque I_g·ω̇ + ω×I_g·ω (pybullet subtracts ω×I_g·ω
    itself), in the body FLU frame (x, −y, −z of FRD).

    Args:
        fossen: the model's :func:`~testbed.vehicle.hydrodynamics.coefficients`.
        rigid: (11,) m, Ixx, Iyy, Izz, r_g (3), r_b − r_g (3), 1/hull height [kg, kg·m², m,
            1/m] (an array: one argument to unbox per call).
        loads: (:data:`N_LOADS`,) the applied body wrench and the current read at
            :data:`LOAD_WRENCH` and :data:`LOAD_CURRENT`; ν̇ written at :data:`LOAD_NU_DOT`.
        height: pybullet's base (CoG) z, up [m].
        orientation: pybullet's base quaternion (x, y, z, w), body FLU → world.
        velocity: pybullet's ``getBaseVelocity`` as it comes: the CoG's velocity and the
            angular velocity, pybullet's world [m/s, rad/s].

    Returns:
        (force, torque) in the body FLU frame [N, N·m].
    """
    linear, angular = velocity
    m, ixx, iyy, izz = rigid[0], rigid[1], rigid[2], rigid[3]
    xg, yg, zg, dbx, dby, dbz, inv_height = (
        rigid[4],
        rigid[5],
        rigid[6],
        rigid[7],
        rigid[8],
        rigid[9],
        rigid[10],
    )
    rotation = matrix_from_quaternion(orientation)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation
    ug, vg, wg, p, q, r = body_velocity(rotation, linear, angular)
    gx, gy, gz = -r20, r21, r22  # NED down in the body: the last row of R_ned
    cn, ce, cd = loads[LOAD_CURRENT], loads[LOAD_CURRENT + 1], loads[LOAD_CURRENT + 2]
    uc = r00 * cn - r10 * ce - r20 * cd
    vc = -(r01 * cn - r11 * ce - r21 * cd)
    wc = -(r02 * cn - r12 * ce - r22 * cd)
    # submerged fraction from the CoB's depth (the CoG's is −height)
    scale = min(1.0, max(0.0, 0.5 + (gx * dbx + gy * dby + gz * dbz - height) * inv_height))
    nu = (ug - q * zg + r * yg, vg - r * xg + p * zg, wg - p * yg + q * xg, p, q, r)
    w = LOAD_WRENCH
    wrench = (loads[w], loads[w + 1], loads[w + 2], loads[w + 3], loads[w + 4], loads[w + 5])
    nu_dot = fossen_acceleration(fossen, nu, (gx, gy, gz), (uc, vc, wc), scale, wrench)
    du, dv, dw, dp, dq, dr = nu_dot
    for i in range(6):
        loads[LOAD_NU_DOT + i] = nu_dot[i]
    force = (
        m * (du + dq * zg - dr * yg + q * wg - r * vg),
        -m * (dv + dr * xg - dp * zg + r * ug - p * wg),
        -m * (dw + dp * yg - dq * xg + p * vg - q * ug),
    )
    torque = (
        ixx * dp + (izz - iyy) * q * r,
        -iyy * dq - (ixx - izz) * r * p,
        -izz * dr - (iyy - ixx) * p * q,
    )
    return force, torque
