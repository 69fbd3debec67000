"""CUDA backend: the CPU kernels' algorithm, one GPU thread per path (design: docs/gpu.md).

The kernels only orchestrate, exactly like ``cpu``: the physics, the integrator step and the
random numbers are the shared scalar functions of ``physics``, ``schemes`` and ``rng``, called
from ``@cuda.jit`` kernels. Everything a path needs is a pure function of (seed, global path
index, step number), so a path takes the same Philox draws on both backends (the same steps,
up to the floating-point differences of a real GPU: docs/gpu.md), and the results do not depend
on the chunking or the launch configuration.

* ``init`` kernel: one thread per path, the initial conditions of ``cpu.init_paths``.
* ``advance`` kernel: one thread per path; position, velocity, noise, time, step counter and the
  Philox counter stay in registers for a whole segment between two output times (or a bounded
  step budget, relaunched until every path has landed on the output time).
* ``accumulate`` kernel: one block per batch. The block's threads evaluate E, E**2, ... for a
  tile of consecutive paths in parallel into shared memory, then thread 0 adds the tile in path
  order, so every batch is summed sequentially in path order with the CPU's exact operations:
  given the same states the float64 sums are bit-identical to ``cpu.accumulate_batches``.
  Histogram counts use atomics (integers: order-independent).

The per-path state stays on the device for a whole chunk; per output time the host reads one
flag (did every path land?), and per chunk it copies back the batch sums, the histogram and the
step counters.

``precision="float32"`` keeps x, Omega and xi in float32 and runs the step in float32
arithmetic. Numba types a Python float literal as float64, so the shared functions called
with float32 arguments would silently compute in float64; the float32 variants used here are
therefore derived mechanically from the shared functions' source at import (every float literal
and float module constant becomes a float32 constant; see ``_float32_variants``), so there is
still a single source of physics. The time, the step counter and the statistics stay float64.
"""

from __future__ import annotations

import ast
import contextlib
import functools
import inspect
import math
import types
import warnings
from typing import Any

import numpy as np
from numba.core.errors import NumbaPerformanceWarning
from numba.extending import register_jitable

from stochpend import physics, rng, schemes
from stochpend._backends import cpu
from stochpend.params import SimulationConfig, hist_edges
from stochpend.progress import NoProgress, Progress
from stochpend.stats import EnsembleSums

try:  # a module global: the CUDA simulator swaps it in the kernels' globals
    from numba import cuda
except Exception as _error:  # pragma: no cover - numba without its CUDA target
    cuda = None
    _IMPORT_ERROR: BaseException | None = _error
else:
    _IMPORT_ERROR = None

__all__ = ["PRECISIONS", "availability", "path_states", "run_batches"]

PRECISIONS = ("float64", "float32")

#: Threads per block of the init and advance kernels (one thread per path).
THREADS_PER_BLOCK = 128
#: Threads per block of the statistics kernel, and paths per shared-memory tile.
STATS_THREADS = 128
#: Histograms with at most this many columns (bins + 2) are counted in shared memory per block.
SHARED_HIST_MAX = 1024
#: Default paths per chunk (57 bytes a path in float64, 41 in float32); capped at half the
#: free device memory.
DEFAULT_CHUNK_PATHS = 1 << 26
#: Path-steps per launch of the advance kernel (a fraction of a second on a recent GPU), and
#: the fewest steps a launch may take. Neither changes any number, only the launch count.
_WORK_PER_LAUNCH = 1 << 31
_MIN_STEPS_PER_LAUNCH = 1000

_U64 = np.uint64
_OU = cpu.OU
_ESCAPE = schemes.ESCAPE_STEP_FRACTION
_WHITE = cpu.WHITE
_DICHOTOMOUS = cpu.DICHOTOMOUS
#: Noises whose state and step run in float64 only.
FLOAT64_ONLY_NOISES = ("dichotomous", "harmonic")
_N_VALUES = 7  # E, E^2, E^3, E^4, Omega^2, Omega^4, G^2: the summed values of a path


# -- availability -----------------------------------------------------------------------------
def _one_line(error: BaseException | None) -> str:
    text = " ".join(str(error).split()).rstrip(" :")
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def availability() -> tuple[bool, str]:
    """Whether kernels can run here, and why (never raises).

    Returns ``(True, description of the device)`` or ``(False, one-line reason)``: numba.cuda
    missing, no CUDA driver, no device, or a device that cannot be opened. Under Numba's CUDA
    simulator (``NUMBA_ENABLE_CUDASIM=1``) it returns True: correct results, very slowly.
    """
    if cuda is None:
        return False, f"numba.cuda cannot be imported ({_one_line(_IMPORT_ERROR)}); install the 'cuda' extra"
    try:
        if _simulator_enabled():
            return True, "Numba CUDA simulator (NUMBA_ENABLE_CUDASIM=1): exact but very slow"
        try:
            n_devices = _device_count()
        except Exception as error:
            return False, f"no usable CUDA driver ({_one_line(error)})"
        if n_devices < 1:
            return False, "the CUDA driver reports no GPU"
        try:
            device = cuda.get_current_device()
            name = device.name.decode() if isinstance(device.name, bytes) else str(device.name)
            cc = ".".join(str(c) for c in device.compute_capability)
        except Exception as error:
            return False, f"the GPU cannot be opened ({_one_line(error)})"
        return True, f"{name} (compute capability {cc})"
    except Exception as error:  # anything unforeseen: report, never raise
        return False, f"CUDA check failed ({_one_line(error)})"


def _device_count() -> int:
    """GPUs the CUDA driver sees; raises if the driver cannot be loaded or initialised."""
    from numba.cuda.cudadrv.driver import driver

    return int(driver.get_device_count())


def _simulator_enabled() -> bool:
    from numba.core import config as numba_config

    return bool(numba_config.ENABLE_CUDASIM)


def _require(precision: str, config: SimulationConfig | None = None) -> None:
    if precision not in PRECISIONS:
        raise ValueError(f"precision={precision!r} is not accepted: one of {', '.join(PRECISIONS)}")
    if precision == "float32" and config is not None and config.noise in FLOAT64_ONLY_NOISES:
        raise ValueError(f"precision='float32' is not accepted with noise={config.noise!r}: "
                         "the dichotomous and harmonic noises run in float64")
    ok, why = availability()
    if not ok:
        raise RuntimeError(f"backend='cuda' is not usable here: {why}")


# -- float32 variants of the shared scalar functions -----------------------------------------
#: The modules whose ``register_jitable`` functions get float32 variants.
_FLOAT32_MODULES = (physics, schemes, rng)
#: The variants the advance kernel calls.
_FLOAT32_ENTRY_POINTS = ("step_size", "ou_step_coefficients", "verlet_step", "draw_normals")
_FLOAT32_MATH_CONSTANTS = ("pi", "e", "tau")
_FLOAT32_ROUNDING = ("floor", "ceil", "trunc")


class _Float32Rewriter(ast.NodeTransformer):
    """Make a shared scalar function compute in float32.

    * a float literal becomes a named float32 constant;
    * ``math.pi`` (and e, tau) becomes a float32 constant;
    * ``float(v)`` becomes ``float32(v)``; ``math.floor(v)`` (an int in Numba) becomes
      ``float32(math.floor(v))``;
    * ``module.function`` of a rewritten function refers to the float32 variant;
    * every returned value is cast to float32 (a branch that Numba types as float64, e.g.
      ``int * x ** n`` of the power potential, would otherwise make the whole function return
      float64), except a call of another variant, which returns float32 already.
    """

    def __init__(self, namespace: dict[str, Any], rewritten: dict[str, set[str]]):
        self.namespace = namespace
        self.rewritten = rewritten
        self.variants = set().union(*rewritten.values())

    def _constant(self, value: float) -> ast.Name:
        name = f"_f32_const_{sum(1 for key in self.namespace if key.startswith('_f32_const_'))}"
        self.namespace[name] = np.float32(value)
        return ast.Name(id=name, ctx=ast.Load())

    def _cast(self, node: ast.expr) -> ast.expr:
        return ast.Call(func=ast.Name(id="_f32", ctx=ast.Load()), args=[node], keywords=[])

    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        if isinstance(node.value, float):
            return self._constant(node.value)
        return node

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        if isinstance(node.value, ast.Name) and isinstance(node.ctx, ast.Load):
            owner, attr = node.value.id, node.attr
            if owner == "math" and attr in _FLOAT32_MATH_CONSTANTS:
                return self._constant(getattr(math, attr))
            if attr in self.rewritten.get(owner, ()):
                return ast.Name(id=attr, ctx=ast.Load())
        return self.generic_visit(node)

    def visit_Return(self, node: ast.Return) -> ast.AST:
        node = self.generic_visit(node)
        value = node.value
        if value is None:
            return node
        if isinstance(value, ast.Tuple):
            value.elts = [self._cast(element) for element in value.elts]
        elif not (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
                  and value.func.id in self.variants):
            node.value = self._cast(value)
        return node

    def visit_Call(self, node: ast.Call) -> ast.AST:
        node = self.generic_visit(node)
        func = node.func
        if isinstance(func, ast.Name) and func.id == "float":
            node.func = ast.Name(id="_f32", ctx=ast.Load())
            return node
        if (isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name)
                and func.value.id == "math" and func.attr in _FLOAT32_ROUNDING):
            return self._cast(node)
        return node


def _as_float32(value: Any) -> Any:
    """Module constants for the variants: floats and tuples of floats become float32."""
    if isinstance(value, (float, np.floating)) and not isinstance(value, np.float32):
        return np.float32(value)
    if isinstance(value, tuple) and value and all(isinstance(v, (float, np.floating)) for v in value):
        return tuple(np.float32(v) for v in value)
    return value


def _is_jitable(node: ast.stmt) -> bool:
    if not isinstance(node, ast.FunctionDef):
        return False
    for decorator in node.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name == "register_jitable":
            return True
    return False


@functools.lru_cache(maxsize=None)
def _float32_variants() -> types.SimpleNamespace:
    """Float32 variants of the shared functions, compiled from their source (single source).

    Every ``register_jitable`` function of ``physics``, ``schemes`` and ``rng`` is re-compiled
    from its current source with the rewrites of ``_Float32Rewriter``, in a namespace holding
    the modules' constants as float32 (integer code such as Philox is unchanged). The results
    are plain Python functions registered with ``register_jitable``, like the originals, so they
    are callable from Python, CPU and CUDA kernels alike. Returns them as a namespace; the
    advance kernel uses ``step_size``, ``ou_step_coefficients``, ``verlet_step`` and
    ``draw_normals``.
    """
    candidates: dict[str, tuple[str, ast.FunctionDef]] = {}
    namespace: dict[str, Any] = {}
    for module in _FLOAT32_MODULES:
        short = module.__name__.rsplit(".", 1)[-1]
        for node in ast.parse(inspect.getsource(module)).body:
            if _is_jitable(node):
                if node.name in candidates:
                    raise RuntimeError(f"float32 variants: two shared modules define {node.name!r}")
                candidates[node.name] = (short, node)
        for name, value in vars(module).items():
            if name.startswith("__"):
                continue
            value = _as_float32(value)
            if name in namespace and not _same(namespace[name], value):
                raise RuntimeError(f"float32 variants: {name!r} means two things in the shared modules")
            namespace[name] = value
    # Only functions that touch floating point (directly or through a call) are rewritten;
    # integer code (the Philox rounds) is used as it is.
    float_names = {
        name for name, value in namespace.items()
        if isinstance(value, np.float32)
        or (isinstance(value, tuple) and value and all(isinstance(v, np.float32) for v in value))
    }
    floaty = {name for name, (_, node) in candidates.items() if _touches_floats(node, float_names)}
    changed = True
    while changed:
        callers = {name for name, (_, node) in candidates.items()
                   if name not in floaty and _calls(node) & floaty}
        floaty |= callers
        changed = bool(callers)
    rewritten: dict[str, set[str]] = {}
    functions = []
    for name, (short, node) in candidates.items():
        if name in floaty:
            rewritten.setdefault(short, set()).add(name)
            functions.append(node)
    names = [node.name for node in functions]
    for node in functions:
        node.decorator_list = []
    module_ast = _Float32Rewriter(namespace, rewritten).visit(ast.Module(body=functions, type_ignores=[]))
    namespace["_f32"] = np.float32
    exec(compile(ast.fix_missing_locations(module_ast), "<stochpend float32 variants>", "exec"), namespace)
    for name in names:
        register_jitable(namespace[name])
    missing = [name for name in _FLOAT32_ENTRY_POINTS if name not in names]
    if missing:
        raise RuntimeError(f"float32 variants: the shared modules no longer define {missing}")
    return types.SimpleNamespace(**{name: namespace[name] for name in names})


def _touches_floats(function: ast.FunctionDef, float_names: set[str]) -> bool:
    for node in ast.walk(function):
        if isinstance(node, ast.Constant) and isinstance(node.value, float):
            return True
        if isinstance(node, ast.Name) and (node.id in float_names or node.id == "float"):
            return True
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "math":
            return True
    return False


def _calls(function: ast.FunctionDef) -> set[str]:
    """Names of the functions called (``f(...)`` or ``module.f(...)``)."""
    called = set()
    for node in ast.walk(function):
        if isinstance(node, ast.Call):
            if isinstance(node.func, ast.Name):
                called.add(node.func.id)
            elif isinstance(node.func, ast.Attribute):
                called.add(node.func.attr)
    return called


def _same(a: Any, b: Any) -> bool:
    if a is b:
        return True
    try:
        return bool(type(a) is type(b) and a == b)
    except Exception:
        return False


def _step_functions(precision: str) -> types.SimpleNamespace:
    if precision == "float32":
        return _float32_variants()
    return types.SimpleNamespace(
        step_size=schemes.step_size,
        ou_step_coefficients=schemes.ou_step_coefficients,
        verlet_step=schemes.verlet_step,
        draw_normals=rng.draw_normals,
    )


# -- device helpers ---------------------------------------------------------------------------
@register_jitable
def hist_column(edges, j, E):
    """Histogram column of E at output time j: 0 below ``edges[j, 0]``, ``n_edges`` at or
    above the last edge, else ``np.searchsorted(edges[j], E, side="right")`` (binary search)."""
    n_edges = edges.shape[1]
    if E < edges[j, 0]:
        return 0
    if E >= edges[j, n_edges - 1]:
        return n_edges
    lo = 0
    hi = n_edges
    while lo < hi:
        mid = (lo + hi) // 2
        if edges[j, mid] > E:
            hi = mid
        else:
            lo = mid + 1
    return lo


@functools.lru_cache(maxsize=None)
def _kernels(precision: str) -> types.SimpleNamespace:
    """Compile-on-first-use kernels for one precision (float64: the shared functions as is)."""

    fns = _step_functions(precision)
    step_size = fns.step_size
    ou_step_coefficients = fns.ou_step_coefficients
    verlet_step = fns.verlet_step
    draw_normals = fns.draw_normals
    real = np.float32 if precision == "float32" else np.float64
    tpb = STATS_THREADS
    hist_max = SHARED_HIST_MAX

    @cuda.jit
    def init_kernel(x, Omega, xi, t, k, status, key0, key1, path0, theta0, uniform_theta0,
                    Omega0, xi0, stationary_xi0, D, tau, noise_code, t_comp, xi_aux,
                    omega_noise):  # pragma: no cover
        """``cpu.init_paths`` for one path per thread (initial values computed in float64);
        also zeroes the clock's compensation term ``t_comp``."""
        i = cuda.grid(1)
        if i >= x.shape[0]:
            return
        x0, O0, xi_0, xa_0 = schemes.initial_state(key0, key1, _U64(path0 + i), theta0,
                                                   uniform_theta0, Omega0, xi0, stationary_xi0,
                                                   D, tau, noise_code, omega_noise)
        x[i] = x0
        Omega[i] = O0
        xi[i] = xi_0
        xi_aux[i] = xa_0
        t[i] = 0.0
        t_comp[i] = 0.0
        k[i] = 0
        status[i] = 0

    @cuda.jit
    def advance_kernel(x, Omega, xi, t, k, status, t_target, max_steps, noise_code, D, tau,
                       omega2, h_max, step_c, potential_code, power_n, coupling_code, key0, key1,
                       path0, unfinished, t_comp, xi_aux, omega_noise):  # pragma: no cover
        """``cpu.advance_paths`` for one path per thread; sets ``unfinished[0] = 1`` if the
        path stopped short of ``t_target`` (step budget spent).

        The clock is the CPU's Kahan-compensated sum, but its compensation term is kept per
        path in ``t_comp`` between launches (zeroed on landing), so that the result does not
        depend on how a segment is split into launches; the CPU restarts it at every call,
        which is the same whenever a segment fits in one call."""
        i = cuda.grid(1)
        if i >= x.shape[0]:
            return
        if status[i] != 0 or t[i] >= t_target:
            return
        D_r = real(D)
        tau_r = real(tau)
        omega2_r = real(omega2)
        h_max_r = real(h_max)
        c_r = real(step_c)
        path = _U64(path0 + i)
        xs = x[i]
        Om = Omega[i]
        xn = xi[i]
        xa = xi_aux[i]
        tt = t[i]
        tc = t_comp[i]
        kk = k[i]
        hc = schemes.HARMONIC_NO_COEFFICIENTS
        h_cached = real(-1.0)
        a = real(0.0)
        s_xi = real(0.0)
        m_I = real(0.0)
        c_I = real(0.0)
        s_I = real(0.0)
        pair_draw = _U64(0xFFFFFFFFFFFFFFFF)
        z_even = real(0.0)
        z_odd = real(0.0)
        n = 0
        bad = False
        while n < max_steps:
            h = real(step_size(Om, xn, xs, h_max_r, c_r, omega2_r, potential_code, power_n,
                               coupling_code))
            if h < _ESCAPE * h_max_r:
                bad = True  # running away (see schemes.ESCAPE_STEP_FRACTION)
                break
            # The clock runs in float64 with the float64 h_max when the step is the largest one
            # (float64: exactly the CPU's h; float32: the same step sequence and draws as
            # float64, the dynamics using that step rounded to float32).
            h_clock = h_max if h == h_max_r else np.float64(h)
            h_clock, last, flip, t_land = schemes.landing_or_flip(
                tt, h_clock, t_target, np.float64(xa), noise_code == _DICHOTOMOUS)
            h = real(h_clock)
            if noise_code == _OU:
                w1, w2 = draw_normals(key0, key1, path, _U64(rng.N_FIRST_STEP) + kk)
                z1 = real(w1)
                z2 = real(w2)
                if h != h_cached:
                    ca, cs, cm, cc, ci = ou_step_coefficients(h, D_r, tau_r)
                    a = real(ca)
                    s_xi = real(cs)
                    m_I = real(cm)
                    c_I = real(cc)
                    s_I = real(ci)
                    h_cached = h
                noise_integral = m_I * xn + c_I * z1 + s_I * z2
                xn = a * xn + s_xi * z1
            elif noise_code == _WHITE:
                d = _U64(rng.N_FIRST_STEP) + (kk >> _U64(1))
                if d != pair_draw:
                    w1, w2 = draw_normals(key0, key1, path, d)
                    z_even = real(w1)
                    z_odd = real(w2)
                    pair_draw = d
                z = z_even if (kk & _U64(1)) == 0 else z_odd
                noise_integral = real(math.sqrt(D_r * h) * z)
            elif noise_code == _DICHOTOMOUS:  # float64 only (refused in float32)
                noise_integral = real(xn * h)
            else:  # harmonic, float64 only
                d = _U64(rng.N_FIRST_STEP) + (kk << _U64(1))
                w1, w2 = rng.draw_normals(key0, key1, path, d)
                w3, _ = rng.draw_normals(key0, key1, path, d + _U64(1))
                if h != h_cached:
                    hc = schemes.harmonic_step_coefficients(h, D, tau, omega_noise)
                    h_cached = h
                integral, xi_new, xa_new = schemes.harmonic_noise_step(xn, xa, w1, w2, w3, hc)
                noise_integral = real(integral)
                xn = real(xi_new)
                xa = real(xa_new)
            x_new, Om_new = verlet_step(xs, Om, h, omega2_r, noise_integral, potential_code,
                                        power_n, coupling_code)
            xs = real(x_new)
            Om = real(Om_new)
            if flip:
                u, _ = rng.draw_uniforms(key0, key1, path, _U64(rng.N_FIRST_STEP) + kk)
                xi_new, xa_new = schemes.dichotomous_flip(xn, xa, u, tau)
                xn = real(xi_new)
                xa = real(xa_new)
            kk += _U64(1)
            n += 1
            tt, tc = schemes.advance_clock(tt, tc, h_clock, flip or last, t_land)
            if not (math.isfinite(xs) and math.isfinite(Om) and math.isfinite(xn)
                    and math.isfinite(xa)):
                bad = True
                break
            if last:
                break
        x[i] = xs
        Omega[i] = Om
        xi[i] = xn
        xi_aux[i] = xa
        t[i] = tt
        t_comp[i] = tc
        k[i] = kk
        if bad:
            status[i] = 1
        if not bad and tt < t_target:
            unfinished[0] = 1

    @cuda.jit
    def accumulate_kernel(x, Omega, status, omega2, potential_code, power_n, coupling_code,
                          batch_size, edges, j, sums, hist):  # pragma: no cover - device
        """``cpu.accumulate_batches`` at output time j: block b sums batch b of the chunk into
        ``sums[b, j, :]`` in path order; the histogram counts go to ``hist[j, :]``."""
        b = cuda.blockIdx.x
        tid = cuda.threadIdx.x
        values = cuda.shared.array((_N_VALUES, tpb), np.float64)
        skip = cuda.shared.array(tpb, np.int32)
        shared_hist = cuda.shared.array(hist_max, np.int32)
        n_cols = edges.shape[1] + 1
        in_shared = n_cols <= hist_max
        if in_shared:
            for c in range(tid, n_cols, tpb):
                shared_hist[c] = 0
        cuda.syncthreads()
        n_paths = x.shape[0]
        start = b * batch_size
        stop = min(start + batch_size, n_paths)
        s_count = 0.0
        s_e1 = 0.0
        s_e2 = 0.0
        s_e3 = 0.0
        s_e4 = 0.0
        s_o2 = 0.0
        s_o4 = 0.0
        s_g2 = 0.0
        s_bad = 0.0
        for base in range(start, stop, tpb):
            i = base + tid
            if i < stop:
                counted = False
                E = 0.0
                E2 = 0.0
                O2 = 0.0
                g = 0.0
                if status[i] == 0:
                    xv = np.float64(x[i])
                    ov = np.float64(Omega[i])
                    E = physics.energy(xv, ov, omega2, potential_code, power_n)
                    E2 = E * E
                    O2 = ov * ov
                    g = physics.noise_shape(xv, potential_code, power_n, coupling_code)
                    if math.isfinite(E2 * E2) and math.isfinite(O2 * O2) and math.isfinite(g):
                        counted = True
                    else:
                        # As on the CPU: a finite state with overflowing moments has escaped;
                        # it is frozen as non-finite from now on.
                        status[i] = 1
                skip[tid] = 0 if counted else 1
                if counted:
                    values[0, tid] = E
                    values[1, tid] = E2
                    values[2, tid] = E2 * E
                    values[3, tid] = E2 * E2
                    values[4, tid] = O2
                    values[5, tid] = O2 * O2
                    values[6, tid] = g * g
                    col = hist_column(edges, j, E)
                    if in_shared:
                        cuda.atomic.add(shared_hist, col, 1)
                    else:
                        cuda.atomic.add(hist, (j, col), 1)
            cuda.syncthreads()
            if tid == 0:
                for q in range(min(tpb, stop - base)):
                    if skip[q] != 0:
                        s_bad += 1.0
                    else:
                        s_count += 1.0
                        s_e1 += values[0, q]
                        s_e2 += values[1, q]
                        s_e3 += values[2, q]
                        s_e4 += values[3, q]
                        s_o2 += values[4, q]
                        s_o4 += values[5, q]
                        s_g2 += values[6, q]
            cuda.syncthreads()
        if tid == 0:
            sums[b, j, cpu.S_COUNT] = s_count
            sums[b, j, cpu.S_E1] = s_e1
            sums[b, j, cpu.S_E2] = s_e2
            sums[b, j, cpu.S_E3] = s_e3
            sums[b, j, cpu.S_E4] = s_e4
            sums[b, j, cpu.S_OMEGA2] = s_o2
            sums[b, j, cpu.S_OMEGA4] = s_o4
            sums[b, j, cpu.S_G2] = s_g2
            sums[b, j, cpu.S_NONFINITE] = s_bad
        if in_shared:
            for c in range(tid, n_cols, tpb):
                count = shared_hist[c]
                if count != 0:
                    cuda.atomic.add(hist, (j, c), np.int64(count))

    return types.SimpleNamespace(init=init_kernel, advance=advance_kernel, accumulate=accumulate_kernel)


# -- host side --------------------------------------------------------------------------------
@contextlib.contextmanager
def _quiet():
    """Silence Numba's low-occupancy warnings: a small ensemble or few batches is legitimate."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaPerformanceWarning)
        yield


def _blocks(n: int, per_block: int) -> int:
    return max(1, -(-n // per_block))


class _Chunk:
    """Device arrays of one chunk of paths and the launches that advance them."""

    def __init__(self, config: SimulationConfig, capacity: int, precision: str):
        self.config = config
        self.kernels = _kernels(precision)
        real = np.float32 if precision == "float32" else np.float64
        self.capacity = capacity
        self.x = cuda.device_array(capacity, dtype=real)
        self.Omega = cuda.device_array(capacity, dtype=real)
        self.xi = cuda.device_array(capacity, dtype=real)
        self.t = cuda.device_array(capacity, dtype=np.float64)
        self.t_comp = cuda.device_array(capacity, dtype=np.float64)
        self.xi_aux = cuda.device_array(capacity, dtype=real)
        self.k = cuda.device_array(capacity, dtype=np.uint64)
        self.status = cuda.device_array(capacity, dtype=np.uint8)
        self.flag = cuda.device_array(1, dtype=np.int32)
        self._zero_flag = np.zeros(1, dtype=np.int32)
        self.key0, self.key1 = rng.seed_to_key(config.seed)
        self.n = 0
        self.p0 = 0

    def views(self) -> tuple:
        n = self.n
        return self.x[:n], self.Omega[:n], self.xi[:n], self.t[:n], self.k[:n], self.status[:n]

    def start(self, p0: int, n: int) -> None:
        """Initial conditions of global paths p0 .. p0 + n - 1."""
        c = self.config
        self.p0, self.n = p0, n
        self.kernels.init[_blocks(n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
            *self.views(), self.key0, self.key1, p0,
            0.0 if c.theta0 is None else c.theta0, c.theta0 is None,
            c.Omega0, 0.0 if c.xi0 is None else c.xi0, c.xi0 is None,
            c.D, c.tau_or_zero, c.noise_code, self.t_comp[:n], self.xi_aux[:n],
            c.omega_noise_or_zero,
        )

    def advance(self, t_target: float, max_steps: int) -> bool:
        """One launch towards t_target; True when every live path has landed on it."""
        c = self.config
        self.flag.copy_to_device(self._zero_flag)
        self.kernels.advance[_blocks(self.n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
            *self.views(), t_target, max_steps, c.noise_code, c.D, c.tau_or_zero, c.omega**2,
            c.h_max, c.step_c, c.potential_code, c.power_n,
            c.coupling_code, self.key0, self.key1, self.p0, self.flag,
            self.t_comp[: self.n], self.xi_aux[: self.n], c.omega_noise_or_zero,
        )
        return int(self.flag.copy_to_host()[0]) == 0

    def steps_per_launch(self) -> int:
        return max(_MIN_STEPS_PER_LAUNCH, _WORK_PER_LAUNCH // max(self.n, 1))

    def advance_to(self, t_target: float) -> None:
        max_steps = self.steps_per_launch()
        while not self.advance(t_target, max_steps):
            pass

    def host_state(self) -> dict[str, np.ndarray]:
        names = ("x", "Omega", "xi", "t", "k", "status")
        return {name: view.copy_to_host() for name, view in zip(names, self.views(), strict=True)}


def _default_chunk_paths(precision: str) -> int:
    if _simulator_enabled():
        return DEFAULT_CHUNK_PATHS
    per_path = 4 * np.dtype(precision).itemsize + 8 + 8 + 8 + 1  # x, Omega, xi, xi_aux; t, t_comp, k; status
    free, _ = cuda.current_context().get_memory_info()
    return int(max(1, min(DEFAULT_CHUNK_PATHS, free // (2 * per_path))))


def run_batches(
    config: SimulationConfig,
    first_batch: int,
    stop_batch: int,
    *,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
    precision: str = "float64",
) -> tuple[EnsembleSums, int]:
    """Simulate batches ``first_batch .. stop_batch - 1`` on the GPU and return their sums.

    Same contract as :func:`stochpend.simulate.run_batches` (same batches, the same
    ``EnsembleSums`` layout and histogram, ``path_steps`` counted the same way), without
    checkpoint/resume. ``chunk_paths`` (rounded down to whole batches, at least one) bounds
    the device memory; default: up to 2**26 paths, at most half the free device memory.
    ``precision``: "float64" (default) or "float32" (state and step arithmetic in float32,
    statistics in float64; docs/gpu.md).

    Raises ``ValueError`` for a bad precision or batch range, ``RuntimeError`` (one line, from
    :func:`availability`) when CUDA cannot run here.
    """
    _require(precision, config)
    if not (0 <= first_batch < stop_batch <= config.n_batches):
        raise ValueError(
            f"batches {first_batch}..{stop_batch} are not accepted: need 0 <= first_batch < "
            f"stop_batch <= n_batches = {config.n_batches}"
        )
    with _quiet():
        return _run_batches(config, first_batch, stop_batch, chunk_paths, progress or NoProgress(),
                            precision)


def _run_batches(config: SimulationConfig, first_batch: int, stop_batch: int,
                 chunk_paths: int | None, progress: Progress, precision: str) -> tuple[EnsembleSums, int]:
    kernels = _kernels(precision)
    times = np.asarray(config.times, dtype=np.float64)
    edges = np.ascontiguousarray(hist_edges(config), dtype=np.float64)
    bs = config.batch_size
    n_times = times.size
    n_cols = config.hist_bins + 2
    omega2 = config.omega**2
    pot = config.potential_code
    cpl = config.coupling_code
    total_paths = min(stop_batch * bs, config.paths) - first_batch * bs
    progress.start(total_paths * config.t_max, "simulating")

    chunk_batches = max(1, (chunk_paths or _default_chunk_paths(precision)) // bs)
    chunk_batches = min(chunk_batches, stop_batch - first_batch)
    capacity = min(chunk_batches * bs, total_paths)
    chunk = _Chunk(config, capacity, precision)
    d_edges = cuda.to_device(edges)
    d_sums = cuda.device_array((chunk_batches, n_times, cpu.N_SUMS), dtype=np.float64)
    d_hist = cuda.device_array((n_times, n_cols), dtype=np.int64)
    zero_hist = np.zeros((n_times, n_cols), dtype=np.int64)
    acc = EnsembleSums.empty(config.n_batches, n_times, config.hist_bins)
    path_steps = 0
    done_work = 0.0

    for b0 in range(first_batch, stop_batch, chunk_batches):
        b1 = min(b0 + chunk_batches, stop_batch)
        nb = b1 - b0
        p0 = b0 * bs
        n = min(b1 * bs, config.paths) - p0
        chunk.start(p0, n)
        d_hist.copy_to_device(zero_hist)
        x, Omega, _, t, k, status = chunk.views()
        max_steps = chunk.steps_per_launch()
        for j in range(n_times):
            t_target = float(times[j])
            while True:
                done = chunk.advance(t_target, max_steps)
                reached = n * t_target if done else float(np.sum(t.copy_to_host()))
                progress.update(done_work + reached)
                if done:
                    break
            kernels.accumulate[nb, STATS_THREADS](
                x, Omega, status, omega2, pot, config.power_n, cpl, bs, d_edges, j, d_sums, d_hist
            )
        acc.add_batches(b0, d_sums.copy_to_host()[:nb], d_hist.copy_to_host())
        path_steps += int(np.sum(k.copy_to_host(), dtype=np.uint64))
        done_work += n * config.t_max
    progress.finish()
    return acc, path_steps


def path_states(
    config: SimulationConfig, first_path: int, n_paths: int, *, precision: str = "float64"
) -> dict[str, np.ndarray]:
    """Final state of global paths ``first_path .. first_path + n_paths - 1`` at t_max.

    The paths land on every output time on the way, exactly as in :func:`run_batches`, so this
    is the state the last statistics were taken from. Returns host arrays ``x``, ``Omega``,
    ``xi`` (of the precision's dtype), ``t``, ``k`` (steps taken) and ``status``. For
    path-by-path comparisons with the CPU kernels.
    """
    _require(precision, config)
    if not (0 <= first_path and 1 <= n_paths and first_path + n_paths <= config.paths):
        raise ValueError(f"paths {first_path}..{first_path + n_paths - 1} are not in the ensemble")
    with _quiet():
        chunk = _Chunk(config, n_paths, precision)
        chunk.start(first_path, n_paths)
        for t_target in config.times:
            chunk.advance_to(float(t_target))
        return chunk.host_state()
