"""accuracy="auto" changing an answer (docs/numerics.md): OU noise, D = tau = omega = 1, 2e6 paths,
coarse step controls asked (h_max = 0.2, c = 0.4), run as asked and with accuracy="auto"."""

import time

import stochpend

KW = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=2_000_000, t_max=5.0, times=(1.0, 2.0, 5.0),
          seed=11, h_max=0.2, step_c=0.4)

t0 = time.time()
a = stochpend.simulate(**KW)
ta = time.time() - t0
t0 = time.time()
b = stochpend.simulate(accuracy="auto", **KW)
tb = time.time() - t0
print(f"fixed: {ta:.1f} s, {a.attrs['path_steps']:.3g} path-steps; auto: {tb:.1f} s, "
      f"{b.attrs['path_steps']:.3g} path-steps, level {b.attrs['accuracy_level']}, "
      f"h_max {b.attrs['h_max']}, c {b.attrs['step_c']}, pilot pairs {b.attrs['bias_paths']}")
for name in ("mean_E", "mean_E2", "skewness", "flatness", "mean_Omega2"):
    for j, t in enumerate(a.time.values):
        va, sa = float(a[name][j]), float(a[name + "_stderr"][j])
        vb, sb = float(b[name][j]), float(b[name + "_stderr"][j])
        ba, bsa = float(a[name + "_bias"][j]), float(a[name + "_bias_stderr"][j])
        bb, bsb = float(b[name + "_bias"][j]), float(b[name + "_bias_stderr"][j])
        print(f"{name:12s} t={t:g} fixed {va:.6g}±{sa:.2g} (bias {ba:.3g}±{bsa:.2g})  "
              f"auto {vb:.6g}±{sb:.2g} (bias {bb:.2g}±{bsb:.2g})  change/SE={(vb - va) / sa:+.2f}")
