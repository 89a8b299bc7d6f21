"""Benchmark of the elastic simulation core: frame times, accuracy, force pass.

    python3 benchmarks/sim.py                 # everything (~15-25 min on a loaded 2-core box)
    python3 benchmarks/sim.py --quick         # smaller run: no 30k mesh, 1 min long run
    python3 benchmarks/sim.py --long-minutes 0  # skip the 10-minute stability run

Meshes: hollow head-like ellipsoidal shells (10 x 12 x 10 cm), tetrahedralised lattices of
stiff rubber (E = 1.5 MPa, 1100 kg/m^3, see characters/materials.toml [stiff_rubber]), at the
latex paper's Table 1 sizes (masses/springs 3,744/6,952, 5,664/15,056, 9,978/25,892: thin
shells with springs dropped to the paper's count) and at ~10k/45k and ~30k/130k (2.5 cells
thick, ~4.5 springs per mass). The hand holds the neck (the lowest nodes, pinned) and shakes
it: 2 cm at 3 Hz sideways, 1 cm at 2 Hz up and down (fading in over 0.5 s), under gravity.

The default integrator is projective dynamics with Chebyshev acceleration, 8 iterations per
step longer than 1/40 s and 6 per shorter step (characters.default_integrator). Printed
per mesh and integrator: ms per 1/25 s and 1/60 s frame (median, p90), RMS deviation from a
converged reference (explicit Verlet with steps 4x below its stability limit and the hand
sampled at every one of them), the speed ratio to a plain NumPy explicit integrator in the
same process, and the force pass in springs per second; for the default integrator also the
time of one global solve, measured right after its run.
A picture of the deviation over time goes to docs/img/sim_shaken_head.png.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from characters import (Control, ImplicitEuler, MassSpring, ProjectiveDynamics, Verlet,
                        default_integrator, material)
from characters import kernels
from characters.model import tetrahedral_lattice

ROOT = Path(__file__).resolve().parents[1]
HEAD_RADII = np.array([0.05, 0.06, 0.05])  # [m]: a 10 cm wide, 12 cm tall head


def head_shell(cells: int, thickness: float, *, springs: int | None = None, seed: int = 0):
    """Tetrahedralised ellipsoidal shell: `cells` lattice cells across 10 cm, `thickness` in
    cells. springs: drop randomly chosen diagonal springs down to this count."""
    spacing = 0.1 / cells
    centre = HEAD_RADII.copy()

    def inside(points):
        outer = (((points - centre) / HEAD_RADII) ** 2).sum(1) <= 1
        inner = (((points - centre) / (HEAD_RADII - thickness * spacing)) ** 2).sum(1) >= 1
        return outer & inner

    x, pairs, _ = tetrahedral_lattice((cells, int(round(cells * 1.2)), cells), spacing,
                                      inside=inside)
    if springs is not None and springs < len(pairs):
        length = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
        diagonal = np.flatnonzero(length > 1.01 * spacing)
        drop = np.random.default_rng(seed).choice(diagonal, len(pairs) - springs, replace=False)
        pairs = np.delete(pairs, drop, axis=0)
    return x, pairs, spacing


def rubber_model(x, pairs, spacing):
    rest = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
    rubber = material("stiff_rubber")
    k, c, m = rubber.lattice_parameters(rest, spacing=spacing)
    return MassSpring(x, pairs, stiffness=k, damping=c, mass=m, gravity=(0, 0, -9.81),
                      velocity_damping=rubber.velocity_damping_rate())


def neck(model, spacing):
    z = model.rest_positions[:, 2]
    return np.flatnonzero(z < z.min() + 1.6 * spacing)


def hand(t):
    """(3,) [m] offset of the hand holding the neck at time t [s].

    A hand does not jerk from rest to 0.4 m/s: the shake fades in over the first 0.5 s."""
    envelope = 0.5 * (1 - math.cos(math.pi * t / 0.5)) if t < 0.5 else 1.0
    return envelope * np.array([0.02 * math.sin(2 * math.pi * 3 * t), 0.0,
                                0.01 * math.sin(2 * math.pi * 2 * t)])


def max_frequency(model) -> float:
    """Gershgorin bound on the highest angular frequency [rad/s]: sqrt(max 2 sum k / m)."""
    incident = np.bincount(model.springs[:, 0], model.stiffness, model.node_count) + \
        np.bincount(model.springs[:, 1], model.stiffness, model.node_count)
    return float(np.sqrt(np.max(2 * incident / model.mass)))


def verlet_substeps(model, dt, safety=0.9) -> int:
    """Substeps keeping h below safety x 2 / omega_max."""
    return max(1, math.ceil(dt * max_frequency(model) / (2 * safety)))


def run(model, integrator, dt, frames, pins, *, record=None, progress=None, budget=None):
    """Shake for `frames` steps of dt (fewer if `budget` [s] of wall time runs out, at least
    5); returns per-step seconds, failures, retries and the final state."""
    state = model.state()
    seconds = np.empty(frames)
    failures = 0
    retries = 0
    began = time.perf_counter()
    for n in range(frames):
        if budget is not None and n >= 5 and time.perf_counter() - began > budget:
            seconds = seconds[:n]
            break
        t = (n + 1) * dt
        control = Control(pins=(pins, model.rest_positions[pins] + hand(t)))
        start = time.perf_counter()
        report = integrator.step(model, state, dt, control)
        seconds[n] = time.perf_counter() - start
        failures += not report.ok
        retries += report.retries
        if record is not None:
            record.append(state.x.copy())
        if progress and n % progress == 0 and n:
            print(f"      ... {n}/{frames} steps ({n * dt:.0f} s simulated)", flush=True)
    return seconds, failures, retries, state


def reference_run(model, dt, frames, pins, substeps):
    """Converged reference: explicit Verlet with tiny steps and the hand sampled at every
    substep (the solvers see it once per frame), recorded once per frame."""
    integrator = Verlet(check_energy=False)
    state = model.state()
    h = dt / substeps
    record = []
    for n in range(frames):
        for k in range(1, substeps + 1):
            t = n * dt + k * h
            integrator.step(model, state, h, Control(pins=(pins, model.rest_positions[pins]
                                                           + hand(t))))
        record.append(state.x.copy())
    return record


def numpy_explicit_step(model, x, v, h, pins, goal):
    """The plain NumPy explicit integrator (same scheme as Verlet): the baseline."""
    i, j = model.springs[:, 0], model.springs[:, 1]
    e = x[j] - x[i]
    length = np.sqrt(np.einsum("ij,ij->i", e, e))
    u = e / length[:, None]
    rel = np.einsum("ij,ij->i", v[j] - v[i], u)
    magnitude = model.stiffness * (length - model.rest_length) + model.damping * rel
    f = magnitude[:, None] * u
    force = np.zeros_like(x)
    np.add.at(force, i, f)
    np.subtract.at(force, j, f)
    force += model.mass[:, None] * model.gravity
    v *= math.exp(-model.velocity_damping * h)
    v += h * force / model.mass[:, None]
    v[pins] = (goal - x[pins]) / h
    x += h * v
    x[pins] = goal


def force_pass_rate(model, repeats=200) -> tuple[float, float, float]:
    """Springs per second of the compiled force kernels the integrators use (split passes over
    the model's SpringPlan): (elastic only, elastic + damping), and of the plain fused loop
    (one gather-compute-scatter loop per spring, elastic only) for comparison."""
    rng = np.random.default_rng(1)
    x = model.rest_positions + 1e-4 * rng.normal(size=model.rest_positions.shape)
    v = rng.normal(size=x.shape) * 0.01
    out = np.zeros_like(x)
    plan = model.plan
    rates = []
    for kernel, args in ((kernels.spring_forces_elastic_3d,
                          (x, plan.si, plan.sj, plan.rest_length, plan.stiffness, plan.scratch,
                           out)),
                         (kernels.spring_forces_3d,
                          (x, v, plan.si, plan.sj, plan.rest_length, plan.stiffness,
                           plan.damping, plan.scratch, out)),
                         (kernels.spring_forces_elastic_fused,
                          (x, model.springs, model.rest_length, model.stiffness, out))):
        kernel(*args)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            kernel(*args)
            times.append(time.perf_counter() - start)
        rates.append(model.spring_count / float(np.median(times)))
    return rates[0], rates[1], rates[2]


def global_solve_ms(integrator, model, repeats=50) -> float:
    """Median ms of one prefactored global solve (x, y, z together) of a ProjectiveDynamics
    integrator that has stepped `model`: the part of a frame that slows down most when the
    host contends for cache and memory bandwidth (1.1-1.3 M nonzeros at 30k, by ordering)."""
    factorisation = integrator._factors[model][1]
    rhs = np.array(factorisation.rhs)
    out = np.empty_like(rhs)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        factorisation.solver.solve(rhs, out)
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3


def numpy_explicit_ms(model, dt, frames, pins) -> float:
    """ms per frame of the plain NumPy explicit integrator at its stable substeps (a few
    frames timed)."""
    substeps = verlet_substeps(model, dt)
    state = model.state()
    h = dt / substeps
    sample = min(frames, 3)
    start = time.perf_counter()
    for n in range(sample):
        goal = model.rest_positions[pins] + hand((n + 1) * dt)
        for _ in range(substeps):
            numpy_explicit_step(model, state.x, state.v, h, pins, goal)
    return (time.perf_counter() - start) / sample * 1e3


def integrators(model, dt):
    return {
        "projective (default: 8 it, 6 at <= 1/40 s; Chebyshev)": ProjectiveDynamics(),
        "projective (8 it at every step, Chebyshev)": ProjectiveDynamics(iterations=8),
        "projective (6 it at every step, Chebyshev)": ProjectiveDynamics(iterations=6),
        "projective (10 it, plain)": ProjectiveDynamics(iterations=10, chebyshev_rho=None),
        "implicit Euler (Cholesky PCG)": ImplicitEuler(tolerance=1e-3, max_iterations=200,
                                                       preconditioner="cholesky"),
        "implicit Euler (Jacobi PCG)": ImplicitEuler(tolerance=1e-3, max_iterations=200),
        "Verlet (stable substeps)": Verlet(substeps=verlet_substeps(model, dt)),
    }


def rms_per_frame(trajectory, reference):
    return np.sqrt(np.mean(np.sum((np.asarray(trajectory) - np.asarray(reference)) ** 2, -1),
                           -1))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller run (no 30k mesh)")
    parser.add_argument("--seconds", type=float, default=2.0,
                        help="simulated seconds per timing run (default 2)")
    parser.add_argument("--long-minutes", type=float, default=10.0,
                        help="simulated minutes of the stability run on 10k/45k (0 skips)")
    parser.add_argument("--no-picture", action="store_true")
    parser.add_argument("--meshes", default="table,10k,30k",
                        help="comma-separated subset of table,10k,30k (default all)")
    parser.add_argument("--default-only", action="store_true",
                        help="time only the default integrator and the force pass (no NumPy "
                             "explicit ratio, no other integrators): a quick re-timing")
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the converged reference (no RMS column; much faster)")
    parser.add_argument("--reference-meshes", default="10k",
                        help="meshes whose RMS deviation from the converged reference is "
                             "measured (default 10k; the 30k reference takes ~20 min per rate)")
    args = parser.parse_args(argv)
    if args.quick:
        args.long_minutes = min(args.long_minutes, 1.0)

    unknown = set(args.reference_meshes.split(",")) - {"10k", "30k", ""}
    if unknown:
        parser.error(f"--reference-meshes: unknown {sorted(unknown)}; choose from 10k, 30k")
    chosen = set(args.meshes.split(","))
    unknown = chosen - {"table", "10k", "30k"}
    if unknown:
        parser.error(f"--meshes: unknown {sorted(unknown)}; choose from table, 10k, 30k")
    meshes = []
    if "table" in chosen:
        meshes += [
            ("Table 1 row 2", dict(cells=41, thickness=1.1, springs=6952), 3744),
            ("Table 1 row 3", dict(cells=35, thickness=1.55, springs=15056), 5664),
            ("Table 1 row 4", dict(cells=47, thickness=1.5, springs=25892), 9978),
        ]
    if "10k" in chosen:
        meshes.append(("10k / 45k", dict(cells=36, thickness=2.5), None))
    if "30k" in chosen and not args.quick:
        meshes.append(("30k / 130k", dict(cells=60, thickness=2.5), None))

    print("mop simulation benchmark: stiff rubber head shaken by the hand (3 Hz, 2 cm)")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; timings are wall clock "
          f"on this machine, one thread\n")
    rows = []
    curves = {}
    for label, spec, paper_nodes in meshes:
        bench_mesh(label, spec, paper_nodes, args, rows, curves)
    if args.long_minutes > 0:
        stability_run(args.long_minutes)

    if curves and not args.no_picture:
        picture(curves, ROOT / "docs" / "img" / "sim_shaken_head.png")
    return 0


def bench_mesh(label, spec, paper_nodes, args, rows, curves) -> None:
    """Time one mesh: its force pass, then every integrator at 25 and 60 fps (RMS against the
    converged reference where asked); appends to rows, and to curves for the picture's mesh."""
    x, pairs, spacing = head_shell(**spec)
    model = rubber_model(x, pairs, spacing)
    pins = neck(model, spacing)
    elastic, damped, fused = force_pass_rate(model)
    print(f"== {label}: {model.node_count} masses, {model.spring_count} springs "
          f"({model.spring_count / model.node_count:.2f}/mass), {pins.size} pinned; "
          f"omega_max {max_frequency(model):.0f} rad/s")
    print(f"   force pass: {elastic / 1e6:.0f} M springs/s elastic, {damped / 1e6:.0f} M "
          f"springs/s with damping (plain fused loop: {fused / 1e6:.0f} M springs/s, "
          f"split/fused {elastic / fused:.2f}x; target >= 250 M springs/s)")
    rows.append((label, model.node_count, model.spring_count, "force pass", elastic, damped))
    accuracy_here = (label.split(" / ")[0] in args.reference_meshes.split(",")
                     and not args.no_reference)
    for rate in (25, 60):
        dt = 1.0 / rate
        frames = max(10, int(round(args.seconds * rate)))
        reference = None
        if accuracy_here:
            substeps = 4 * verlet_substeps(model, dt)
            print(f"   reference at {rate} fps: Verlet, {substeps} substeps per frame ...",
                  flush=True)
            reference = reference_run(model, dt, frames, pins, substeps)
        chosen_integrators = integrators(model, dt)
        if args.default_only:
            numpy_ms = math.nan
            chosen_integrators = dict(list(chosen_integrators.items())[:1])
        else:
            numpy_ms = numpy_explicit_ms(model, dt, frames, pins)
            print(f"   {rate} fps: plain NumPy explicit ({verlet_substeps(model, dt)} "
                  f"substeps): {numpy_ms:.1f} ms/frame")
        for name, integrator in chosen_integrators.items():
            integrator.step(model, model.state(), dt)  # compile / factorise outside timing
            record = [] if reference is not None else None
            seconds, failures, retries, _ = run(model, integrator, dt, frames, pins,
                                                record=record,
                                                budget=None if record is not None else 30.0)
            ms = seconds[1:] * 1e3  # the first step includes the factorisation
            rms = (float(np.sqrt(np.mean(rms_per_frame(record, reference) ** 2)))
                   if record is not None else math.nan)
            if record is not None and label == "10k / 45k":  # the picture's mesh
                curves[(rate, name)] = rms_per_frame(record, reference)
            print(f"   {rate} fps {name:37s} median {np.median(ms):7.2f} ms  p90 "
                  f"{np.percentile(ms, 90):7.2f} ms  x{numpy_ms / np.median(ms):7.1f} vs "
                  f"NumPy  RMS {rms * 1e3:6.3f} mm  failures {failures} retries {retries}"
                  f"  ({len(seconds)} frames)",
                  flush=True)
            rows.append((label, model.node_count, model.spring_count, f"{rate} fps {name}",
                         float(np.median(ms)), float(np.percentile(ms, 90)), rms,
                         numpy_ms / np.median(ms), failures))
            if name.startswith("projective (default"):
                print(f"   {rate} fps   of which {integrator.iterations_for(dt)} global "
                      f"solves, {global_solve_ms(integrator, model):.2f} ms each (median, "
                      f"timed after the run)", flush=True)
    if paper_nodes:
        print(f"   (the paper's row: {paper_nodes} masses; ours differs by "
              f"{model.node_count - paper_nodes:+d})")
    print()


def stability_run(minutes: float) -> None:
    """The default integrator on the 10k head for `minutes` simulated minutes at 60 fps."""
    x, pairs, spacing = head_shell(cells=36, thickness=2.5)
    model = rubber_model(x, pairs, spacing)
    pins = neck(model, spacing)
    frames = int(minutes * 60 * 60)
    print(f"== stability: {minutes:g} simulated minutes at 60 fps on "
          f"{model.node_count}/{model.spring_count} with the default integrator")
    integrator = default_integrator()
    seconds, failures, retries, state = run(model, integrator, 1 / 60, frames, pins,
                                            progress=frames // 10)
    drift = np.abs(state.x - model.rest_positions).max()
    finite = bool(np.all(np.isfinite(state.x)))
    print(f"   {frames} steps: failures {failures}, retries {retries}, finite {finite}, "
          f"max displacement at the end {drift * 1e3:.1f} mm, median "
          f"{np.median(seconds) * 1e3:.2f} ms, p90 {np.percentile(seconds, 90) * 1e3:.2f} ms")


def picture(curves, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for ax, rate in zip(axes, (25, 60)):
        for (r, name), curve in curves.items():
            if r == rate:
                ax.plot(np.arange(1, len(curve) + 1) / rate, curve * 1e3, label=name)
        ax.axhline(2.5, color="k", ls=":", lw=1, label="2.5 mm target")
        ax.set_title(f"1/{rate} s steps")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("RMS deviation from reference [mm]")
    axes[1].legend(fontsize=8)
    fig.suptitle("10k/45k stiff-rubber head shaken by the hand: deviation from converged "
                 "explicit reference", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"picture: {path.relative_to(ROOT)}")


if __name__ == "__main__":
    raise SystemExit(main())
