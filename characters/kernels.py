"""Compiled array kernels of the simulation core (numba, cached compilation).

Pure functions: they read arrays and write into arrays they are given; no allocation inside the
per-step kernels. Classes in model.py / integrators.py / constraints.py pick which to call; tests
compare them with plain NumPy references.

Shapes: x, v, f : (N, d) float64 [m, m/s, N]; springs : (M, 2) int32; rest, k, c : (M,) float64.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# fastmath: reassociation and FMA for the force sums; kernels that must see NaN/inf
# (all_finite) are compiled without it
_JIT = dict(cache=True, nogil=True, fastmath=True, error_model="numpy")


# --- forces ---------------------------------------------------------------------------------

@njit(**_JIT)
def _length2(x, i, j):
    """|x_j - x_i|^2 for x (N, d)."""
    total = 0.0
    for a in range(x.shape[1]):
        e = x[j, a] - x[i, a]
        total += e * e
    return total


@njit(**_JIT)
def spring_forces(x, v, springs, rest, k, c, out):
    """Add every spring's elastic + along-spring damping force to out (N, d) [N].

    One fused loop per spring, any d: the 2D models' force pass, and the plain reference the
    split 3D kernels below are tested against."""
    d = x.shape[1]
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        length2 = _length2(x, i, j)
        length = np.sqrt(length2)
        inv = 1.0 / length if length > 0.0 else 0.0
        rel = 0.0
        for a in range(d):
            rel += (v[j, a] - v[i, a]) * (x[j, a] - x[i, a])
        mag = k[s] * (length - rest[s]) + c[s] * rel * inv
        for a in range(d):
            fa = mag * (x[j, a] - x[i, a]) * inv
            out[i, a] += fa
            out[j, a] -= fa


# --- split spring passes (3D), the per-step force kernels ------------------------------------
#
# One fused loop per spring (gather, sqrt and divide, scatter) runs ~42 scalar instructions per
# spring and tops out near 180 M springs/s here. Split in three passes it is ~1.6x faster:
# the gather writes edge vectors contiguously, the arithmetic then runs as a plain loop over
# arrays that the compiler turns into AVX vector code (sqrt and divide included), and the
# scatter walks springs sorted by their first node, summing that node's share in registers
# and writing it once per run. Indices are uint32: no negative-index wraparound code.
# The passes run chunk by chunk of scratch.shape[1] springs (SPLIT_CHUNK in a model's plan), so
# the scratch rows stay in the L2 cache instead of streaming 6 x 8 bytes per spring through
# memory; in the projective step this leaves the Cholesky factor in the L3 cache (30k/130k
# head: 30k frame 39.3 -> 32.9 ms in the best of alternating runs). The rows are passed as 1-D
# slices: a 2-D slice of the scratch would be typed non-contiguous and not vectorised.
# si, sj : (M,) uint32, si <= sj, sorted by si (see model.SpringPlan); per-spring arrays in
# that order; scratch : (6, C) float64, C >= 1, reused every call.

SPLIT_CHUNK = 4096  # springs per chunk: 6 rows x 4096 x 8 bytes = 192 KiB of scratch


@njit(**_JIT)
def gather_rows(x, si, sj, ex, ey, ez):
    """(ex, ey, ez) (M,) [m] = x[sj] - x[si] for x (N, 3); x[si] is read once per run of equal
    si."""
    m = si.shape[0]
    if m == 0:
        return
    i = si[0]
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    for s in range(m):
        n = si[s]
        if n != i:
            i = n
            xi = x[i, 0]
            yi = x[i, 1]
            zi = x[i, 2]
        j = sj[s]
        ex[s] = x[j, 0] - xi
        ey[s] = x[j, 1] - yi
        ez[s] = x[j, 2] - zi


@njit(**_JIT)
def scatter_rows(si, sj, fx, fy, fz, out):
    """out[si] += f, out[sj] -= f for rows f = (fx, fy, fz) (M,), out (N, 3); si sorted for
    speed (any order gives the same sums)."""
    m = si.shape[0]
    if m == 0:
        return
    i = si[0]
    ax = 0.0
    ay = 0.0
    az = 0.0
    for s in range(m):
        n = si[s]
        if n != i:
            out[i, 0] += ax
            out[i, 1] += ay
            out[i, 2] += az
            i = n
            ax = 0.0
            ay = 0.0
            az = 0.0
        j = sj[s]
        ax += fx[s]
        ay += fy[s]
        az += fz[s]
        out[j, 0] -= fx[s]
        out[j, 1] -= fy[s]
        out[j, 2] -= fz[s]
    out[i, 0] += ax
    out[i, 1] += ay
    out[i, 2] += az


@njit(**_JIT)
def _elastic_magnitudes(ex, ey, ez, rest, k):
    """e := (k (1 - r / l)) e in place, e = (ex, ey, ez) rows; zero-length springs give zero.
    The same arithmetic as _damped_magnitudes without its damping term, so an undamped model
    gets the same forces from either."""
    for s in range(ex.shape[0]):
        length2 = ex[s] * ex[s] + ey[s] * ey[s] + ez[s] * ez[s]
        inv = 1.0 / np.sqrt(length2) if length2 > 0.0 else 0.0
        mag = k[s] * (1.0 - rest[s] * inv)
        ex[s] *= mag
        ey[s] *= mag
        ez[s] *= mag


@njit(**_JIT)
def _damped_magnitudes(ex, ey, ez, vx, vy, vz, rest, k, c):
    """e := (k (1 - r / l) + c (dv . e) / l^2) e in place, e = (ex, ey, ez), dv = (vx, vy, vz)
    rows."""
    for s in range(ex.shape[0]):
        length2 = ex[s] * ex[s] + ey[s] * ey[s] + ez[s] * ez[s]
        inv = 1.0 / np.sqrt(length2) if length2 > 0.0 else 0.0
        rel = vx[s] * ex[s] + vy[s] * ey[s] + vz[s] * ez[s]
        mag = k[s] * (1.0 - rest[s] * inv) + c[s] * rel * inv * inv
        ex[s] *= mag
        ey[s] *= mag
        ez[s] *= mag


# what _split_passes computes per spring between its gather and its scatter
_DAMPED, _ELASTIC = 0, 1


@njit(**_JIT)
def _split_passes(x, y, si, sj, p, q, r, kind, scratch, out):
    """Gather, per-spring arithmetic `kind`, scatter into out (N, 3), chunk by chunk of
    scratch.shape[1] springs. y (N, 3) is gathered too for _DAMPED (velocities); p, q, r (M,)
    are the per-spring arrays of that kind, in plan order."""
    m = si.shape[0]
    chunk = scratch.shape[1]
    for s0 in range(0, m, chunk):
        s1 = min(s0 + chunk, m)
        n = s1 - s0
        ex, ey, ez = scratch[0][:n], scratch[1][:n], scratch[2][:n]
        wx, wy, wz = scratch[3][:n], scratch[4][:n], scratch[5][:n]
        a = si[s0:s1]
        b = sj[s0:s1]
        gather_rows(x, a, b, ex, ey, ez)
        if kind == _DAMPED:
            gather_rows(y, a, b, wx, wy, wz)
            _damped_magnitudes(ex, ey, ez, wx, wy, wz, p[s0:s1], q[s0:s1], r[s0:s1])
        else:
            _elastic_magnitudes(ex, ey, ez, p[s0:s1], q[s0:s1])
        scatter_rows(a, b, ex, ey, ez, out)


@njit(**_JIT)
def spring_forces_3d(x, v, si, sj, rest, k, c, scratch, out):
    """Add every spring's elastic + along-spring damping force to out (N, 3) [N] (split passes;
    the same sums as spring_forces)."""
    _split_passes(x, v, si, sj, rest, k, c, _DAMPED, scratch, out)


@njit(**_JIT)
def spring_forces_elastic_3d(x, si, sj, rest, k, scratch, out):
    """Elastic part only (no damping), split passes: the force pass of benchmarks/sim.py."""
    _split_passes(x, x, si, sj, rest, k, k, _ELASTIC, scratch, out)


@njit(**_JIT)
def spring_forces_elastic_fused(x, springs, rest, k, out):
    """Elastic part only, one fused loop per spring: the plain compiled reference the split
    kernel is measured against in benchmarks/sim.py."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        ex = x[j, 0] - x[i, 0]
        ey = x[j, 1] - x[i, 1]
        ez = x[j, 2] - x[i, 2]
        length2 = ex * ex + ey * ey + ez * ez
        mag = k[s] * (1.0 - rest[s] / np.sqrt(length2)) if length2 > 0.0 else 0.0
        out[i, 0] += mag * ex
        out[i, 1] += mag * ey
        out[i, 2] += mag * ez
        out[j, 0] -= mag * ex
        out[j, 1] -= mag * ey
        out[j, 2] -= mag * ez


@njit(**_JIT)
def spring_energy(x, springs, rest, k):
    """sum k (l - r)^2 / 2 [J]."""
    total = 0.0
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        length2 = _length2(x, i, j)
        stretch = np.sqrt(length2) - rest[s]
        total += 0.5 * k[s] * stretch * stretch
    return total


@njit(**_JIT)
def node_forces(x, v, mass, gravity, velocity_damping, target_index, target_position,
                target_stiffness, target_damping, force_index, force_value, out):
    """Add gravity, velocity damping, target pulls and external forces to out (N, d) [N].

    target_index (T,) int, target_position (T, d) [m], target_stiffness (T,) [N/m],
    target_damping (T,) [N s/m]; force_index (F,) int, force_value (F, d) [N].
    """
    n, d = x.shape
    for i in range(n):
        m = mass[i]
        for a in range(d):
            out[i, a] += m * (gravity[a] - velocity_damping * v[i, a])
    for t in range(target_index.shape[0]):
        i = target_index[t]
        for a in range(d):
            out[i, a] += (target_stiffness[t] * (target_position[t, a] - x[i, a])
                          - target_damping[t] * v[i, a])
    for t in range(force_index.shape[0]):
        i = force_index[t]
        for a in range(d):
            out[i, a] += force_value[t, a]


# --- explicit update ------------------------------------------------------------------------

@njit(**_JIT)
def symplectic_update(x, v, f, inverse_mass, dt, retention):
    """Position Verlet in velocity form: v <- retention v + dt f / m; x <- x + dt v.

    Identical to x_{n+1} = x_n + retention (x_n - x_{n-1}) + dt^2 f / m with v = dx / dt;
    nodes with inverse_mass 0 (fixed, pinned) keep their position and velocity untouched.
    """
    n, d = x.shape
    for i in range(n):
        w = inverse_mass[i]
        if w == 0.0:
            continue
        for a in range(d):
            vi = retention * v[i, a] + dt * w * f[i, a]
            v[i, a] = vi
            x[i, a] += dt * vi


@njit(cache=True, nogil=True)  # no fastmath here: it would assume away NaN and inf
def all_finite(a):
    flat = a.ravel()
    for i in range(flat.shape[0]):
        if not np.isfinite(flat[i]):
            return False
    return True


@njit(**_JIT)
def kinetic_energy(v, mass, inverse_mass):
    n, d = v.shape
    total = 0.0
    for i in range(n):
        if inverse_mass[i] == 0.0:
            continue
        s = 0.0
        for a in range(d):
            s += v[i, a] * v[i, a]
        total += 0.5 * mass[i] * s
    return total


# --- implicit Euler (Baraff-Witkin) -----------------------------------------------------------

@njit(**_JIT)
def implicit_assemble(x, v, springs, rest, k, c, h, blocks, diag, f, kv):
    """One pass over springs for the linearised backward-Euler system.

    Writes blocks (M, d, d) = h^2 K_s + h D_s (the off-diagonal block is minus this), adds the
    same to diag (N, d, d) at both ends, adds spring forces to f (N, d) [N] and K v to kv (N, d)
    [N/s]. K_s = k (u u^T + max(1 - r/l, 0) (I - u u^T)) is the spring's stiffness block with
    the transverse term clamped at zero for compressed springs, which keeps the system definite;
    D_s = c u u^T its damping block.
    """
    d = x.shape[1]
    u = np.empty(d)
    dv = np.empty(d)
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        length2 = 0.0
        for a in range(d):
            e = x[j, a] - x[i, a]
            u[a] = e
            length2 += e * e
        length = np.sqrt(length2)
        inv = 1.0 / length if length > 0.0 else 0.0
        rel = 0.0
        for a in range(d):
            u[a] *= inv
            dv[a] = v[j, a] - v[i, a]
            rel += dv[a] * u[a]
        ks = k[s]
        mag = ks * (length - rest[s]) + c[s] * rel
        transverse = 1.0 - rest[s] * inv
        if transverse < 0.0:
            transverse = 0.0
        along = h * h * ks + h * c[s]
        across = h * h * ks * transverse
        for a in range(d):
            f[i, a] += mag * u[a]
            f[j, a] -= mag * u[a]
            kva = 0.0
            for b in range(d):
                uu = u[a] * u[b]
                block = (along - across) * uu
                kblock = ks * (uu + transverse * ((1.0 if a == b else 0.0) - uu))
                if a == b:
                    block += across
                blocks[s, a, b] = block
                diag[i, a, b] += block
                diag[j, a, b] += block
                kva += kblock * dv[b]
            kv[i, a] += kva
            kv[j, a] -= kva


@njit(**_JIT)
def block_matvec(springs, blocks, diag, z, out):
    """out = A z for A with diagonal blocks diag (N, d, d), off-diagonal -blocks[s] at (i, j)."""
    n, d = z.shape
    if d == 3:
        _block_matvec_3d(springs, blocks, diag, z, out)
        return
    for i in range(n):
        for a in range(d):
            acc = 0.0
            for b in range(d):
                acc += diag[i, a, b] * z[i, b]
            out[i, a] = acc
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        for a in range(d):
            acc_i = 0.0
            acc_j = 0.0
            for b in range(d):
                acc_i += blocks[s, a, b] * z[j, b]
                acc_j += blocks[s, a, b] * z[i, b]
            out[i, a] -= acc_i
            out[j, a] -= acc_j


@njit(**_JIT)
def _block_matvec_3d(springs, blocks, diag, z, out):
    for i in range(z.shape[0]):
        z0 = z[i, 0]
        z1 = z[i, 1]
        z2 = z[i, 2]
        out[i, 0] = diag[i, 0, 0] * z0 + diag[i, 0, 1] * z1 + diag[i, 0, 2] * z2
        out[i, 1] = diag[i, 1, 0] * z0 + diag[i, 1, 1] * z1 + diag[i, 1, 2] * z2
        out[i, 2] = diag[i, 2, 0] * z0 + diag[i, 2, 1] * z1 + diag[i, 2, 2] * z2
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        # spring blocks are symmetric: read the upper triangle only
        b00 = blocks[s, 0, 0]
        b01 = blocks[s, 0, 1]
        b02 = blocks[s, 0, 2]
        b11 = blocks[s, 1, 1]
        b12 = blocks[s, 1, 2]
        b22 = blocks[s, 2, 2]
        zi0 = z[i, 0]
        zi1 = z[i, 1]
        zi2 = z[i, 2]
        zj0 = z[j, 0]
        zj1 = z[j, 1]
        zj2 = z[j, 2]
        out[i, 0] -= b00 * zj0 + b01 * zj1 + b02 * zj2
        out[i, 1] -= b01 * zj0 + b11 * zj1 + b12 * zj2
        out[i, 2] -= b02 * zj0 + b12 * zj1 + b22 * zj2
        out[j, 0] -= b00 * zi0 + b01 * zi1 + b02 * zi2
        out[j, 1] -= b01 * zi0 + b11 * zi1 + b12 * zi2
        out[j, 2] -= b02 * zi0 + b12 * zi1 + b22 * zi2


@njit(**_JIT)
def cg_step(solution, residual, direction, product, alpha):
    """solution += alpha direction; residual -= alpha product (in place)."""
    fs = solution.ravel()
    fr = residual.ravel()
    fd = direction.ravel()
    fp = product.ravel()
    for t in range(fs.shape[0]):
        fs[t] += alpha * fd[t]
        fr[t] -= alpha * fp[t]


@njit(**_JIT)
def cg_direction(direction, preconditioned, beta):
    """direction = preconditioned + beta direction (in place)."""
    fd = direction.ravel()
    fz = preconditioned.ravel()
    for t in range(fd.shape[0]):
        fd[t] = fz[t] + beta * fd[t]


@njit(**_JIT)
def invert_blocks(diag, free, out):
    """out[i] = inverse of diag[i] (d <= 3) for free nodes, zero for constrained ones."""
    n, d = diag.shape[0], diag.shape[1]
    for i in range(n):
        if free[i] == 0.0:
            for a in range(d):
                for b in range(d):
                    out[i, a, b] = 0.0
            continue
        if d == 2:
            a00, a01, a10, a11 = diag[i, 0, 0], diag[i, 0, 1], diag[i, 1, 0], diag[i, 1, 1]
            det = a00 * a11 - a01 * a10
            out[i, 0, 0] = a11 / det
            out[i, 0, 1] = -a01 / det
            out[i, 1, 0] = -a10 / det
            out[i, 1, 1] = a00 / det
        else:
            m = diag[i]
            c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
            c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
            c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
            det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
            inv = 1.0 / det
            out[i, 0, 0] = c00 * inv
            out[i, 1, 0] = c01 * inv
            out[i, 2, 0] = c02 * inv
            out[i, 0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) * inv
            out[i, 1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) * inv
            out[i, 2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) * inv
            out[i, 0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) * inv
            out[i, 1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) * inv
            out[i, 2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) * inv


@njit(**_JIT)
def _apply_blocks(blocks, r, out):
    n, d = r.shape
    for i in range(n):
        for a in range(d):
            acc = 0.0
            for b in range(d):
                acc += blocks[i, a, b] * r[i, b]
            out[i, a] = acc


@njit(**_JIT)
def _dot(a, b):
    fa = a.ravel()
    fb = b.ravel()
    acc = 0.0
    for i in range(fa.shape[0]):
        acc += fa[i] * fb[i]
    return acc


@njit(**_JIT)
def block_pcg(system, rhs, solution, work, tolerance, max_iterations):
    """Block-Jacobi preconditioned CG on A solution = rhs, over free nodes only.

    system = (springs (M, 2) int, blocks, diag, diag_inverse, free (N,) float): the matrix as
    block_matvec takes it, its inverted diagonal blocks and the free-node mask; work = (r, z,
    p, q), four (N, d) scratch arrays. Constrained nodes (free[i] == 0) keep their entries of
    `solution` (prescribed values); their equations are dropped and their columns act through
    the residual. The initial `solution` is the warm start. Stops when |r|_M^-1 <= tolerance
    |rhs|_M^-1. Returns the iteration count.
    """
    springs, blocks, diag, diag_inverse, free = system
    r, z, p, q = work
    n, d = rhs.shape
    block_matvec(springs, blocks, diag, solution, q)
    for i in range(n):
        for a in range(d):
            r[i, a] = (rhs[i, a] - q[i, a]) * free[i]
    _apply_blocks(diag_inverse, r, z)
    rz = _dot(r, z)
    for i in range(n):
        for a in range(d):
            p[i, a] = z[i, a]
    # the stopping scale: the preconditioned norm of the right-hand side
    for i in range(n):
        for a in range(d):
            q[i, a] = rhs[i, a] * free[i]
    _apply_blocks(diag_inverse, q, z)
    scale = _dot(q, z)
    for i in range(n):
        for a in range(d):
            z[i, a] = p[i, a]
    target = tolerance * tolerance * scale
    iteration = 0
    while iteration < max_iterations and rz > target and rz > 0.0:
        block_matvec(springs, blocks, diag, p, q)
        for i in range(n):
            for a in range(d):
                q[i, a] *= free[i]
        pq = _dot(p, q)
        if pq <= 0.0:
            break
        alpha = rz / pq
        for i in range(n):
            for a in range(d):
                solution[i, a] += alpha * p[i, a]
                r[i, a] -= alpha * q[i, a]
        _apply_blocks(diag_inverse, r, z)
        rz_new = _dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            for a in range(d):
                p[i, a] = z[i, a] + beta * p[i, a]
        iteration += 1
    return iteration


@njit(**_JIT)
def implicit_update(x, v, dv, free, h):
    """v <- v + dv; x <- x + h v on free nodes (constrained ones are set by the caller)."""
    n, d = x.shape
    for i in range(n):
        if free[i] == 0.0:
            continue
        for a in range(d):
            vi = v[i, a] + dv[i, a]
            v[i, a] = vi
            x[i, a] += h * vi


# --- projective dynamics (Liu et al. 2013) -------------------------------------------------

@njit(**_JIT)
def pd_base_rhs(start, spring_set, nodes, h, velocity_damping, out):
    """The part of the global right-hand side that is fixed during one step.

    start = (x0, v0, accel, known), each (N, d): the step's start positions [m] and velocities
    [m/s], external accelerations [m/s^2], and the end-of-step positions of pinned/fixed nodes
    [m]; spring_set = (springs (M, 2) int, k (M,) [N/m], c (M,) [N s/m]); nodes = (mass (N,)
    [kg], free_nodes (F,) int, free_id (N,) int: a free node's row, -1 for a known node).
    Row free_id[i] of out belongs to free node i (rows of known nodes are left alone):
    out = M y + h c_vd M x0 + h C_L x0 + (h^2 L + h C_L) couplings to known nodes,
    with y = x0 + h v0 + h^2 accel the inertial prediction.
    """
    x0, v0, accel, known = start
    springs, k, c = spring_set
    mass, free_nodes, free_id = nodes
    d = x0.shape[1]
    for f in range(free_nodes.shape[0]):
        i = free_nodes[f]
        row = free_id[i]
        m = mass[i]
        for a in range(d):
            y = x0[i, a] + h * v0[i, a] + h * h * accel[i, a]
            out[row, a] = m * y + h * velocity_damping * m * x0[i, a]
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        fi = free_id[i]
        fj = free_id[j]
        hc = h * c[s]
        couple = h * h * k[s] + hc
        for a in range(d):
            rel = hc * (x0[i, a] - x0[j, a])
            if fi >= 0:
                out[fi, a] += rel
                if fj < 0:
                    out[fi, a] += couple * known[j, a]
            if fj >= 0:
                out[fj, a] -= rel
                if fi < 0:
                    out[fj, a] += couple * known[i, a]


@njit(**_JIT)
def _set_known_rows(known_index, known, out):
    for t in range(known_index.shape[0]):
        i = known_index[t]
        for a in range(out.shape[1]):
            out[i, a] = known[i, a]


@njit(**_JIT)
def pd_local_rhs(x, springs, weight, base, known_index, known, out):
    """Local step fused with the right-hand side: out = base + h^2 J d(x), known rows = known.

    d_s = r_s (x_j - x_i) / |x_j - x_i| is spring s projected onto its rest length r_s;
    weight (M,) = h^2 k_s r_s, so each spring adds weight_s (x_j - x_i) / |x_j - x_i|.
    One fused loop, any d (2D models; the reference for pd_local_rhs_3d).
    """
    d = x.shape[1]
    out[...] = base
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        length2 = _length2(x, i, j)
        scale = weight[s] / np.sqrt(length2) if length2 > 0.0 else 0.0
        for a in range(d):
            pa = scale * (x[j, a] - x[i, a])
            out[j, a] += pa
            out[i, a] -= pa
    _set_known_rows(known_index, known, out)


@njit(**_JIT)
def pd_local_rhs_damped(x, x_start, springs, weight, damping_h, base, known_index, known, out):
    """pd_local_rhs plus the correction that makes spring damping act along springs only.

    The global matrix damps relative velocity isotropically (h C_L, constant, so it can be
    prefactored); here the transverse part of that, h c (I - u u^T) (w_j - w_i) with
    w = x - x_start = h v, is handed back on the right-hand side at the current iterate, so
    the fixed point damps only along each spring (rigid rotation is not braked).
    damping_h (M,) = h c_s [kg]. Fused loops, any d (2D; the reference for pd_local_rhs_3d).
    """
    d = x.shape[1]
    pd_local_rhs(x, springs, weight, base, known_index, known, out)
    for s in range(springs.shape[0]):
        hc = damping_h[s]
        if hc == 0.0:
            continue
        i = springs[s, 0]
        j = springs[s, 1]
        length2 = 0.0
        along = 0.0
        for a in range(d):
            e = x[j, a] - x[i, a]
            length2 += e * e
            along += e * ((x[j, a] - x_start[j, a]) - (x[i, a] - x_start[i, a]))
        if length2 == 0.0:
            continue
        along /= length2
        for a in range(d):
            w = (x[j, a] - x_start[j, a]) - (x[i, a] - x_start[i, a])
            corr = hc * (w - along * (x[j, a] - x[i, a]))
            out[j, a] += corr
            out[i, a] -= corr
    _set_known_rows(known_index, known, out)


@njit(**_JIT)
def _pd_projections(ex, ey, ez, gx, gy, gz, weight):
    """e := -(weight / l + (g . e) / l^2) e in place, e = (ex, ey, ez), g = (gx, gy, gz) rows
    (M,): minus what pd_local_rhs_3d adds to node j (scatter_rows adds f to i, takes it from
    j)."""
    for s in range(ex.shape[0]):
        length2 = ex[s] * ex[s] + ey[s] * ey[s] + ez[s] * ez[s]
        if length2 > 0.0:
            inv2 = 1.0 / length2
            mag = -(weight[s] * np.sqrt(inv2)
                    + (gx[s] * ex[s] + gy[s] * ey[s] + gz[s] * ez[s]) * inv2)
        else:
            mag = 0.0
        ex[s] *= mag
        ey[s] *= mag
        ez[s] *= mag


@njit(**_JIT)
def pd_local_rhs_3d(x, si, sj, weight, start_damping, base, known_index, known, scratch, out):
    """pd_local_rhs_damped for 3D models in split passes, with base from pd_base_rhs_3d.

    weight (M,) in plan order; start_damping (3, M) [kg m] = h c_s (x0_j - x0_i), the step's
    start edges, from pd_base_rhs_3d. With w = e - e0 (e = x_j - x_i, e0 its value at the
    step's start) the transverse damping h c (w - (w . u) u) equals h c ((e0 . u) u - e0): its
    constant part -h c e0 cancels the isotropic damper term h c (x0_j - x0_i) of the fused
    base, which pd_base_rhs_3d leaves out, so each iteration adds only
    (weight / l + (h c e0 . e) / l^2) e per spring: one gather of x, no moves.
    """
    out[...] = base
    m = si.shape[0]
    chunk = scratch.shape[1]
    gx, gy, gz = start_damping[0], start_damping[1], start_damping[2]
    for s0 in range(0, m, chunk):
        s1 = min(s0 + chunk, m)
        n = s1 - s0
        ex, ey, ez = scratch[0][:n], scratch[1][:n], scratch[2][:n]
        a = si[s0:s1]
        b = sj[s0:s1]
        gather_rows(x, a, b, ex, ey, ez)
        _pd_projections(ex, ey, ez, gx[s0:s1], gy[s0:s1], gz[s0:s1], weight[s0:s1])
        scatter_rows(a, b, ex, ey, ez, out)
    _set_known_rows(known_index, known, out)


@njit(**_JIT)
def pd_base_rhs_3d(start, plan, boundary, nodes, h, velocity_damping, out, start_damping):
    """The fixed right-hand side of a 3D step for pd_local_rhs_3d (free_id is the identity on
    free nodes here): pd_base_rhs without the isotropic damper term, which cancels against the
    local step's transverse damping, and start_damping (3, M) = h c (x0_j - x0_i) in plan
    order for the local step.

    start = (x0, v0, accel, known) as for pd_base_rhs; plan = (si, sj (M,) int64, damping_h
    (M,) = h c), in plan order; boundary = (couple_free, couple_known (B,) int64 [node], couple
    (B,) [kg]): the springs with exactly one known end, h^2 k + h c, which pull their free end
    towards the known end's position; nodes = (mass (N,) [kg], free_nodes (F,) int). Rows of
    known nodes receive stray sums: the local step overwrites them.
    """
    x0, v0, accel, known = start
    si, sj, damping_h = plan
    couple_free, couple_known, couple = boundary
    mass, free_nodes = nodes
    for f in range(free_nodes.shape[0]):
        i = free_nodes[f]
        m = mass[i]
        for a in range(3):
            y = x0[i, a] + h * v0[i, a] + h * h * accel[i, a]
            out[i, a] = m * y + h * velocity_damping * m * x0[i, a]
    gx, gy, gz = start_damping[0], start_damping[1], start_damping[2]
    gather_rows(x0, si, sj, gx, gy, gz)
    for s in range(si.shape[0]):
        hc = damping_h[s]
        gx[s] *= hc
        gy[s] *= hc
        gz[s] *= hc
    for b in range(couple_free.shape[0]):
        i = couple_free[b]
        j = couple_known[b]
        for a in range(3):
            out[i, a] += couple[b] * known[j, a]


@njit(**_JIT)
def spring_energy_3d(x, si, sj, rest, k, scratch):
    """sum k (l - r)^2 / 2 [J] for x (N, 3), split passes (rest, k in plan order)."""
    m = si.shape[0]
    chunk = scratch.shape[1]
    total = 0.0
    for s0 in range(0, m, chunk):
        s1 = min(s0 + chunk, m)
        n = s1 - s0
        ex, ey, ez = scratch[0][:n], scratch[1][:n], scratch[2][:n]
        gather_rows(x, si[s0:s1], sj[s0:s1], ex, ey, ez)
        for s in range(n):
            stretch = np.sqrt(ex[s] * ex[s] + ey[s] * ey[s] + ez[s] * ez[s]) - rest[s0 + s]
            total += 0.5 * k[s0 + s] * stretch * stretch
    return total


# --- a projective-dynamics step's start and end (exact: numpy's arithmetic, no fastmath) ----

@njit(cache=True, nogil=True)
def pd_step_start(x, v, x_start, v_start, known, pin_index, pin_goal):
    """x_start, v_start := x, v; known := x with the pinned rows at pin_goal (P, d)."""
    n, d = x.shape
    for i in range(n):
        for a in range(d):
            x_start[i, a] = x[i, a]
            v_start[i, a] = v[i, a]
            known[i, a] = x[i, a]
    for p in range(pin_index.shape[0]):
        for a in range(d):
            known[pin_index[p], a] = pin_goal[p, a]


@njit(cache=True, nogil=True)
def pd_warm_start(x, v, h, base, x_start, targets, known_index, known, previous):
    """The targets' share of the fixed right-hand side, base[t] += h^2 k_t p_t + h c_t x0_t
    (targets: (index (T,), position (T, d), stiffness (T,), damping (T,)), indices distinct),
    then the first iterate x += h v with known rows at known, and previous := x (previous of
    shape (0, d): not kept)."""
    target_index, target_position, target_stiffness, target_damping = targets
    d = x.shape[1]
    hh = h * h
    for t in range(target_index.shape[0]):
        i = target_index[t]
        stiffness = hh * target_stiffness[t]
        damping = h * target_damping[t]
        for a in range(d):
            base[i, a] += stiffness * target_position[t, a] + damping * x_start[i, a]
    for i in range(x.shape[0]):
        for a in range(d):
            x[i, a] += h * v[i, a]
    _set_known_rows(known_index, known, x)
    if previous.shape[0]:
        previous[...] = x


@njit(cache=True, nogil=True)
def pd_step_end(x, x_start, h, v):
    """v := (x - x_start) / h."""
    n, d = x.shape
    for i in range(n):
        for a in range(d):
            v[i, a] = (x[i, a] - x_start[i, a]) / h


@njit(**_JIT)
def chebyshev_update(current, solved, previous, omega, gamma):
    """Chebyshev semi-iterative step (Wang 2015), in place:
    new = omega (gamma (solved - current) + current - previous) + previous;
    previous <- current; current <- new."""
    flat_c = current.ravel()
    flat_s = solved.ravel()
    flat_p = previous.ravel()
    for t in range(flat_c.shape[0]):
        cur = flat_c[t]
        prev = flat_p[t]
        flat_c[t] = omega * (gamma * (flat_s[t] - cur) + cur - prev) + prev
        flat_p[t] = cur


@njit(**_JIT)
def gravity_work(x, x_ref, mass, inverse_mass, gravity):
    """Gravity potential of x relative to x_ref: -sum m g . (x - x_ref) [J] over free nodes."""
    n, d = x.shape
    total = 0.0
    for i in range(n):
        if inverse_mass[i] == 0.0:
            continue
        s = 0.0
        for a in range(d):
            s += gravity[a] * (x[i, a] - x_ref[i, a])
        total -= mass[i] * s
    return total

