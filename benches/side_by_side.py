#!/usr/bin/env python3
"""The objective's value + gradient of `benches/evaluation.rs` with JAX and with pykeops on CPU,
side by side with medial's fused kernel (not run by CI).

The same objective as the benchmark: forward Euler flow of the landmarks q (N = 40 steps,
q^{n+1} = q^n + dt K(q^n) u^n, K_ij = exp(-|q_i - q_j|^2 / (2 sigma^2))), kinetic energy
KE = (dt/2) sum_n u^n . K u^n with weight 0.05, and SSD = sum_i |q^N_i - (q_i + (1, -0.5, 0.25))|^2,
at the benchmark's smooth momenta, on its three cases (t001 k = 503, sigma = 2; the KeOps
hippocampus k = 2,000 and 6,611, sigma = 5).

- JAX: the dense objective (k x k kernel matrices), differentiated by jax.value_and_grad,
  jit-compiled, each step rematerialised in the backward pass (jax.checkpoint: storing
  N dense matrices of 6,611^2 would not fit), float64.
- pykeops: the forward sums K u and the adjoint's two sums per step (the same discrete adjoint
  as medial's) as KeOps reductions (pykeops.numpy, no torch), float64.
- medial: the criterion median of `value_and_gradient_N40/fused` from the same machine.

Usage, from the repository root, in a virtual environment with jax and pykeops:
    python3 -m venv venv && venv/bin/pip install jax pykeops numpy
    venv/bin/python benches/side_by_side.py [--skip-bench] [--repeats 5]
It runs `cargo bench -p medial --bench evaluation -- value_and_gradient_N40/fused` (which also
writes the cases' landmarks), unless --skip-bench reuses the last run's results.

`--in-fit` compares instead the cost of an evaluation inside a whole fit: the release binary
fits the KeOps reduced hippocampus (k = 662, a plain mesh) to its own points moved by a smooth
warp (written by this script: the KeOps tutorial's reduced target is not in correspondence),
with flow, kinetic energy and SSD (the benchmark's objective), the automatic settings but
N = 40 steps; its seconds per evaluation (L-BFGS, line search and every check included;
`summary.json`) are set against JAX's and pykeops's value + gradient at the same landmarks,
kernel width and N.
"""

import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

STEPS = 40
KINETIC_WEIGHT = 0.05
SHIFT = np.array([1.0, -0.5, 0.25])
CASES = ["t001", "hippo2000", "hippo6611"]
ROOT = pathlib.Path(__file__).resolve().parent.parent
TARGET = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))


def read_case(path):
    """Landmarks (k x 3) and sigma from a file written by benches/evaluation.rs."""
    lines = path.read_text().splitlines()
    sigma = float(lines[0].split("=")[1])
    q = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    return q, sigma


def momenta(q):
    """The benchmark's smooth momenta, N x k x 3."""
    n = np.arange(STEPS)[:, None]
    return np.stack(
        [
            np.broadcast_to(np.sin(0.1 * q[:, 1]), (STEPS, len(q))),
            np.cos(0.1 * q[:, 2] + 0.01 * n),
            np.full((STEPS, len(q)), 0.3),
        ],
        axis=-1,
    )


def best_of(repeats, run):
    """Median wall time of `repeats` runs after one warm-up (compilation), and the result."""
    result = run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def jax_value_and_grad(q, sigma):
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    targets = jnp.asarray(q + SHIFT)
    q0 = jnp.asarray(q)
    dt = 1.0 / STEPS

    @jax.checkpoint
    def step(carry, un):
        x, ke = carry
        d2 = jnp.sum((x[:, None, :] - x[None, :, :]) ** 2, axis=-1)
        v = jnp.exp(-d2 / (2 * sigma * sigma)) @ un
        return (x + dt * v, ke + 0.5 * dt * jnp.sum(un * v)), None

    def energy(u):
        (x, ke), _ = jax.lax.scan(step, (q0, 0.0), u)
        return KINETIC_WEIGHT * ke + jnp.sum((x - targets) ** 2)

    f = jax.jit(jax.value_and_grad(energy))

    def run(u):
        value, grad = f(u)
        return float(value), np.asarray(grad.block_until_ready())

    return run


def keops_value_and_grad(q, sigma):
    from pykeops.numpy import Genred

    gamma = np.array([0.5 / (sigma * sigma)])
    kernel = "Exp(-g * SqDist(x, y))"
    variables = ["g = Pm(1)", "x = Vi(3)", "y = Vj(3)"]
    # sum_j K_ij b_j
    smooth = Genred(f"{kernel} * b", variables + ["b = Vj(3)"], reduction_op="Sum", axis=1)
    # sum_j K_ij (a_i . u_j + u_i . b_j) (q_i - q_j)
    adjoint = Genred(
        f"{kernel} * ((a | v) + (w | c)) * (x - y)",
        variables + ["a = Vi(3)", "v = Vj(3)", "w = Vi(3)", "c = Vj(3)"],
        reduction_op="Sum",
        axis=1,
    )
    targets = q + SHIFT
    dt = 1.0 / STEPS

    def run(u):
        path, ke = [q], 0.0
        for un in u:
            v = smooth(gamma, path[-1], path[-1], un)
            ke += 0.5 * dt * np.sum(un * v)
            path.append(path[-1] + dt * v)
        a = 2.0 * (path[-1] - targets)
        grad = np.empty_like(u)
        for n in reversed(range(STEPS)):
            x, un = path[n], u[n]
            b = a + KINETIC_WEIGHT * un
            grad[n] = dt * smooth(gamma, x, x, b)
            a = a - dt / (sigma * sigma) * adjoint(gamma, x, x, a, un, un, b)
        value = KINETIC_WEIGHT * ke + np.sum((path[-1] - targets) ** 2)
        return float(value), grad

    return run


def medial_seconds(name, k):
    estimates = (
        TARGET / "criterion/value_and_gradient_N40/fused" / f"{name}_k{k}" / "new/estimates.json"
    )
    return json.loads(estimates.read_text())["median"]["point_estimate"] * 1e-9


def fit_seconds_per_evaluation(workdir):
    """Landmarks, sigma and seconds per evaluation of the release binary's fit of the reduced
    KeOps hippocampus in N = 40 steps (automatic settings otherwise)."""
    data = ROOT.parent / "shared/data/keops"
    subprocess.run(["cargo", "build", "--release", "-p", "medial-cli"], cwd=ROOT, check=True)
    medial = TARGET / "release/medial"
    template, target = data / "hippos_reduc_source.vtk", workdir / "warped.vtk"
    write_warped(template, target)
    auto = workdir / "automatic"
    fit = [str(medial), "fit", "--quiet"]
    subprocess.run(fit + ["--template", str(template), "--target", str(target), "--out", str(auto)], check=True, stdout=subprocess.DEVNULL)
    config = (auto / "config.toml").read_text()
    config, steps = re.subn(r"(?m)^time_steps = \d+$", f"time_steps = {STEPS}", config)
    assert steps == 1, "no time_steps in the resolved config"
    (workdir / "n40.toml").write_text(config)
    subprocess.run(fit + [str(workdir / "n40.toml"), "--out", str(workdir / "n40")], check=True, stdout=subprocess.DEVNULL)
    summary = json.loads((workdir / "n40/summary.json").read_text())
    seconds = sum(s["seconds"] for s in summary["stages"])
    evaluations = sum(s["evaluations"] for s in summary["stages"])
    sigma = float(re.search(r"(?m)^sigma = (.+)$", config).group(1))
    return read_vtk_points(template), sigma, seconds / evaluations, evaluations


def read_vtk_points(path):
    """The points of a legacy ASCII VTK polydata file."""
    words = path.read_text().split()
    n = int(words[words.index("POINTS") + 1])
    start = words.index("POINTS") + 3
    return np.array(words[start : start + 3 * n], dtype=float).reshape(n, 3)


def write_warped(source, out):
    """`source`'s points moved by a smooth warp of a few millimetres (vertex i to vertex i)."""
    q = read_vtk_points(source)
    x, y, z = q.T
    moved = q + np.stack([2 * np.sin(0.1 * y), 2 * np.cos(0.1 * z) - 1, 0.05 * (x - x.mean())], axis=1)
    text = source.read_text()
    head, rest = text.split("POINTS", 1)
    polygons = rest[rest.index("POLYGONS") :]
    points = "\n".join(" ".join(f"{c:.6f}" for c in p) for p in moved)
    out.write_text(f"{head}POINTS {len(q)} double\n{points}\n{polygons}")


def compare(name, q, sigma, ours, repeats):
    """Times the two peers on landmarks `q` and prints their ratios to `ours` (seconds)."""
    u = momenta(q)
    jax_run, keops_run = jax_value_and_grad(q, sigma), keops_value_and_grad(q, sigma)
    t_jax, (_, g_jax) = best_of(repeats, lambda: jax_run(u))
    t_keops, (_, g_keops) = best_of(repeats, lambda: keops_run(u))
    diff = np.linalg.norm(g_jax - g_keops) / np.linalg.norm(g_jax)
    print(
        f"{name:<10} {len(q):>6} {ours * 1e3:>8.1f}ms {t_jax * 1e3:>8.1f}ms {t_keops * 1e3:>8.1f}ms "
        f"{t_jax / ours:>10.1f}x {t_keops / ours:>12.1f}x {diff:>10.1e}"
    )
    sys.stdout.flush()


HEADER = (
    f"{'case':<10} {'k':>6} {'medial':>10} {'JAX':>10} {'pykeops':>10} {'JAX/medial':>11} "
    f"{'keops/medial':>13} {'grad diff':>10}"
)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-bench", action="store_true", help="reuse the last criterion run")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per peer (median)")
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    parser.add_argument("--in-fit", action="store_true", help="time a whole fit at k = 662, N = 40")
    args = parser.parse_args()
    if args.in_fit:
        with tempfile.TemporaryDirectory() as workdir:
            q, sigma, ours, evaluations = fit_seconds_per_evaluation(pathlib.Path(workdir))
        print(f"medial fit of the reduced hippocampus, N = {STEPS}: {evaluations} evaluations")
        print(HEADER)
        compare("in-fit", q, sigma, ours, args.repeats)
        return
    cases_dir = pathlib.Path(os.environ.get("MEDIAL_BENCH_CASES") or tempfile.mkdtemp())
    if not args.skip_bench:
        env = dict(os.environ, MEDIAL_BENCH_CASES=str(cases_dir))
        subprocess.run(
            ["cargo", "bench", "-p", "medial", "--bench", "evaluation", "--", "value_and_gradient_N40/fused"],
            cwd=ROOT,
            env=env,
            check=True,
        )
    print(HEADER)
    for name in args.cases.split(","):
        q, sigma = read_case(cases_dir / f"{name}.csv")
        compare(name, q, sigma, medial_seconds(name, len(q)), args.repeats)


if __name__ == "__main__":
    main()
