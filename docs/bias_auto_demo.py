"""accuracy="auto" changing an answer: OU D = tau = omega = 1, 2e6 paths, coarse controls asked (docs/numerics.md)."""
import time, stochpend, numpy as np
kw = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=2_000_000, t_max=5.0, times=(1.0, 2.0, 5.0), seed=11, h_max=0.2, step_c=0.4)
t=time.time(); a = stochpend.simulate(**kw); ta=time.time()-t
t=time.time(); b = stochpend.simulate(accuracy="auto", **kw); tb=time.time()-t
print(f"fixed: {ta:.1f} s, {a.attrs['path_steps']:.3g} path-steps; auto: {tb:.1f} s, {b.attrs['path_steps']:.3g} path-steps, level {b.attrs['accuracy_level']}, h_max {b.attrs['h_max']}, c {b.attrs['step_c']}, pilot pairs {b.attrs['bias_paths']}")
for name in ("mean_E","mean_E2","skewness","flatness","mean_Omega2"):
    for j,t in enumerate(a.time.values):
        va, sa = float(a[name][j]), float(a[name+"_stderr"][j]); vb, sb = float(b[name][j]), float(b[name+"_stderr"][j])
        ba, bsa = float(a[name+"_bias"][j]), float(a[name+"_bias_stderr"][j]); bb, bsb = float(b[name+"_bias"][j]), float(b[name+"_bias_stderr"][j])
        print(f"{name:12s} t={t:g} fixed {va:.6g}±{sa:.2g} (bias {ba:.3g}±{bsa:.2g})  auto {vb:.6g}±{sb:.2g} (bias {bb:.2g}±{bsb:.2g})  change/SE={(vb-va)/sa:+.2f}")
