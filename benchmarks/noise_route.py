"""Follow ``noise`` from ``stochpend.simulate`` (issue 33, "the route of noise"): every call into a
stochpend function that receives the noise (its name, the Noise object, or a config or spec that
holds it) as an argument, in a warm run of 200 paths. Prints the modules entered, in order, and
the climbs back up: calls whose callee sits in a higher layer (tests/unit/test_layers.py) than
its caller. Usage: ``PYTHONPATH=src python benchmarks/noise_route.py .`` (the repository root).
"""
import importlib
import json
import sys

sys.path.insert(0, sys.argv[1])  # repo root (for tests.unit.test_layers)
import stochpend

layers_mod = importlib.import_module("tests.unit.test_layers")

def layer(mod):
    short = mod[len("stochpend."):] if mod.startswith("stochpend.") else ""
    if hasattr(layers_mod, "_layer"):
        return layers_mod._layer(short)
    return layers_mod._layer_of().get(short, 99)

NOISE_NAMES = {"ou"}
def carries(v, depth=0):
    if isinstance(v, str):
        return v in NOISE_NAMES
    t = type(v).__module__ or ""
    if t.startswith("stochpend") and type(v).__name__ in ("OU", "Noise", "OUNoise"):
        return True
    if depth == 0 and t.startswith("stochpend"):
        for name in ("noise", "config", "spec"):
            w = getattr(v, name, None) if not isinstance(v, type) else None
            if w is not None and w is not v and carries(w, 1):
                return True
    return False

events = []
def prof(frame, event, arg):
    if event != "call":
        return
    mod = frame.f_globals.get("__name__", "")
    if not mod.startswith("stochpend"):
        return
    code = frame.f_code
    args = [frame.f_locals.get(n) for n in code.co_varnames[:code.co_argcount + code.co_kwonlyargcount]]
    if any(carries(a) for a in args):
        caller = frame.f_back
        cmod = caller.f_globals.get("__name__", "") if caller else ""
        events.append((cmod, mod, code.co_name))

ds = stochpend.simulate(noise="ou", paths=200, t_max=1, times=[1.0], seed=1)  # warm
events.clear()
sys.setprofile(prof)
try:
    stochpend.simulate(noise="ou", paths=200, t_max=1, times=[1.0], seed=1)
finally:
    sys.setprofile(None)
mods = []
for _c, m, _f in events:
    if m not in mods:
        mods.append(m)
climbs = [(c, m, f) for c, m, f in events if c.startswith("stochpend") and c != m and layer(m) > layer(c)]
print(json.dumps({"modules": len(mods), "calls": len(events), "climbs": len(climbs),
                  "module_list": mods, "climb_list": sorted(set(f"{c} -> {m}.{f}" for c, m, f in climbs))}, indent=1))
