"""The same workload in diffrax on JAX (CPU): Heun + UnsafeBrownianPath, vmap over paths.

Run as a script in a separate virtual environment that has ``jax`` and ``diffrax``
(``/work/main/.venv-bench``; see benchmarks/README.md)::

    .venv-bench/bin/python benchmarks/diffrax_ref.py --paths 10000 --t-max 100 --h 0.01

It prints one JSON line: path-steps/s of the second (compiled) call, the first call's time
(trace + XLA compile + run), peak RSS, ⟨E²⟩/(Dt/τ²) at t_max. It imports nothing of stochpend.

The SDE is the pendulum with the OU noise as a third state variable, in Stratonovich form
(Heun converges to the Stratonovich solution; for this system Itô = Stratonovich):

    dθ = Ω dt,  dΩ = -(ω² + ξ) sin θ dt,  dξ = -ξ/τ dt + (√D/τ) dW.

Initial conditions are stochpend's: θ uniform on [-π, π), Ω = 0, ξ stationary N(0, D/(2τ)),
drawn from JAX's own generator (so the numbers differ from stochpend's, the law is the same).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time


def build(paths: int, t_max: float, h: float, D: float, tau: float, omega: float):
    import diffrax
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    omega2 = omega * omega
    sigma = math.sqrt(D) / tau
    n_steps = int(math.ceil(t_max / h - 1e-9))

    def drift(t, y, args):
        theta, Omega, xi = y[0], y[1], y[2]
        return jnp.stack([Omega, -(omega2 + xi) * jnp.sin(theta), -xi / tau])

    def diffusion(t, y, args):
        return jnp.array([[0.0], [0.0], [sigma]])

    def one_path(key):
        k_theta, k_xi, k_bm = jax.random.split(key, 3)
        theta0 = jax.random.uniform(k_theta, (), minval=-math.pi, maxval=math.pi)
        xi0 = math.sqrt(D / (2.0 * tau)) * jax.random.normal(k_xi, ())
        y0 = jnp.stack([theta0, jnp.zeros(()), xi0])
        bm = diffrax.UnsafeBrownianPath(shape=(1,), key=k_bm)
        terms = diffrax.MultiTerm(diffrax.ODETerm(drift), diffrax.ControlTerm(diffusion, bm))
        sol = diffrax.diffeqsolve(
            terms, diffrax.Heun(), t0=0.0, t1=t_max, dt0=h, y0=y0,
            saveat=diffrax.SaveAt(t1=True), max_steps=n_steps + 16,
            adjoint=diffrax.DirectAdjoint(),
        )
        y = sol.ys[0]
        theta, Omega = y[0], y[1]
        E = 0.5 * Omega * Omega - omega2 * jnp.cos(theta)
        return E, sol.stats["num_accepted_steps"]

    @jax.jit
    def ensemble(seed):
        keys = jax.random.split(jax.random.PRNGKey(seed), paths)
        E, steps = jax.vmap(one_path)(keys)
        return jnp.mean(E * E), jnp.max(steps)

    return ensemble


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--paths", type=int, default=10_000)
    p.add_argument("--t-max", type=float, default=100.0)
    p.add_argument("--h", type=float, default=0.01)
    p.add_argument("--D", type=float, default=1.0)
    p.add_argument("--tau", type=float, default=1.0)
    p.add_argument("--omega", type=float, default=1.0)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    t_start = time.perf_counter()
    try:
        import diffrax
        import jax
    except ImportError as exc:  # reported as "not available"
        print(json.dumps({"available": False, "reason": f"{type(exc).__name__}: {exc}"}))
        return 0
    t_import = time.perf_counter() - t_start
    ensemble = build(args.paths, args.t_max, args.h, args.D, args.tau, args.omega)
    t0 = time.perf_counter()
    m2, steps = ensemble(args.seed)
    m2 = float(m2)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    c0 = time.process_time()
    m2b, steps = ensemble(args.seed + 1)
    m2b = float(m2b)
    second = time.perf_counter() - t0
    second_cpu = time.process_time() - c0
    steps = int(steps)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out = {
        "available": True,
        "jax_version": jax.__version__,
        "diffrax_version": diffrax.__version__,
        "python_version": sys.version.split()[0],
        "paths": args.paths,
        "steps": steps,
        "import_s": t_import,
        "first_call_s": first,
        "steady_s": second,
        "steady_cpu_s": second_cpu,
        "compile_s": max(first - second, 0.0),
        "path_steps_per_s": args.paths * steps / second,
        "E2_scaled": m2b / (args.D * args.t_max / args.tau**2),
        "E2_scaled_first": m2 / (args.D * args.t_max / args.tau**2),
        "peak_rss_mb": ru.ru_maxrss / 1024.0,
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
