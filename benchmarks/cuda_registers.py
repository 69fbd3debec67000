"""Registers, spills and stack of the CUDA kernels for sm_90 (H100), compiled offline: no GPU needed.

Run it in the CUDA tools environment (``make cuda-registers`` creates ``.venv-cuda`` with the
pinned versions of ``benchmarks/cuda-tools.txt`` and runs this script)::

    make cuda-registers
    make cuda-registers CUDA_ARGS="--filter float64 --out out/registers.md"
    PYTHONPATH=src .venv-cuda/bin/python benchmarks/cuda_registers.py [--filter S] [--out FILE]
        [--lto] [--ref GIT_REF] [--ptx-dir DIR] [--subset all|ci]
    python benchmarks/cuda_registers.py --compare BEFORE.md AFTER.md

What it does, per kernel variant:

1. Numba-cuda compiles the kernel's Python function for the given argument types to PTX for
   compute capability 9.0 (``cuda.compile_ptx``). Numba-cuda asks the driver for "the current
   device" when it compiles the device functions a kernel calls; without a driver that lookup
   is stubbed to report compute capability (9, 0) (``numba.cuda.dispatcher.get_current_device``,
   docs/gpu.md, "Developer notes"). Nothing else touches the driver, so no GPU and no CUDA
   driver are needed.
2. ``ptxas -arch=sm_90 -v`` (from the ``nvidia-cuda-nvcc-cu12`` wheel) assembles the PTX and
   reports, per kernel (``.entry``): registers per thread, spill stores and loads (bytes per
   thread, local memory), and the stack frame (bytes per thread).
3. From the PTX: instruction counts that show where a kernel leaves its precision or word size:
   float64 arithmetic (``add/sub/mul/fma/div/sqrt/rcp/setp/selp/... .f64``; loads, stores, moves
   and conversions not counted), conversions to or from float64 (``cvt`` with ``f64``), 64-bit
   integer multiplies (``mul.lo``/``mul.hi``/``mad`` on ``s64``/``u64``) and 32 x 32-bit
   products (``mul.wide.u32``, ``mul.hi.u32``). Static counts (each instruction once, whether it
   runs once or in a loop; libdevice slow paths included).
4. From the registers alone: how many warps an SM of sm_90 can hold with 128-thread blocks
   (65536 registers per SM, allocated per warp in units of 256, whole blocks of 4 warps,
   at most 64 warps), as a share of the 64 warps. Shared memory and the other limits are
   ignored: this is the register ceiling on occupancy.

The kernels are compiled with the options of their ``@cuda.jit`` dispatcher when one is given
(fastmath, opt, debug, lineinfo, launch_bounds, max_registers), else with ``@cuda.jit``'s
defaults (no fastmath, opt=3, no debug info).

``--lto``: link through nvJitLink with link-time optimisation first (LTO-IR from NVVM, then
PTX from nvJitLink, then ptxas), which is the path a ``@cuda.jit`` kernel takes when it is
launched and nvJitLink >= 12.3 is installed (numba-cuda's default ``lto``; ``numba-cuda[cu12]``
installs nvJitLink). Without it, the plain ``compile_ptx`` PTX is measured. The two can differ
by a few registers; compare numbers only within one mode and one toolkit version.

Which kernels: if ``stochpend.engine.cuda`` has ``kernel_variants()``, the triples
``(label, kernel, signature)`` it returns (``kernel`` a Python function or a ``@cuda.jit``
dispatcher; ``signature`` a Numba signature or a tuple of Numba types, as ``compile_ptx``
accepts). Otherwise the advance kernel of the current backend in float64 and float32, with the
argument types the host code launches it with.

``--ref GIT_REF`` measures ``src/`` as committed at that revision (exported with ``git
archive`` into a temporary directory; the working tree is not touched), for a baseline while
``src/`` is being changed.

``--compare BEFORE.md AFTER.md`` compiles nothing: it reads two tables this script wrote (with
``--out``) and lists every kernel in both whose registers changed, with its occupancy limit
before and after, then a summary line. Exit status 1 when a kernel has more registers after
than before, or a kernel of AFTER spills or failed to compile: issue 33's "no kernel with more
registers, no spills" as a command. Labels are compared after :data:`LABEL_RENAMES` (the
additive OU channel's label changed with the channel's rewrite).

``--subset ci`` keeps a representative subset (:func:`in_ci_subset`: every kernel kind, 85 of
214 kernels); ``make cuda-compile-check [CUDA_CHECK=ci]`` is ``--lto --subset ...`` with the table
in ``out/cuda-compile-check.md``, a compile check for CI.

Exit status: 0 on success; 2 when numba-cuda or ptxas is missing (``make cuda-registers``
installs them) or no kernel matches ``--filter``; 1 when a kernel fails to compile.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import inspect
import io
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
import types
import warnings
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INSTALL_HINT = "run `make cuda-registers` (creates .venv-cuda with the pinned CUDA tools)"

#: Target: H100 (compute capability 9.0).
CC = (9, 0)
ARCH = f"sm_{CC[0]}{CC[1]}"
#: sm_90 register file and allocation rules (CUDA occupancy calculator).
REGS_PER_SM = 65536
REG_ALLOC_UNIT = 256  # registers, allocated per warp
MAX_WARPS_PER_SM = 64
MAX_BLOCKS_PER_SM = 32
WARP_SIZE = 32
THREADS_PER_BLOCK = 128

#: The advance kernel of stochpend before 248dd5c (measured with --ref), its arguments in order, with the types its host passed (see
#: ``_Chunk.advance`` in src/stochpend/engine/cuda.py): device arrays are 1-d C-contiguous;
#: Python floats are float64, Python ints int64, the Philox keys np.uint64. "real" is the
#: precision's dtype (x, Omega, xi, xi_aux).
ADVANCE_ARGS = (
    ("x", "real[:]"), ("Omega", "real[:]"), ("xi", "real[:]"), ("t", "float64[:]"),
    ("k", "uint64[:]"), ("status", "uint8[:]"), ("t_target", "float64"), ("max_steps", "int64"),
    ("noise_code", "int64"), ("D", "float64"), ("tau", "float64"), ("omega2", "float64"),
    ("h_max", "float64"), ("step_c", "float64"), ("potential_code", "int64"),
    ("power_n", "int64"), ("coupling_code", "int64"), ("key0", "uint64"), ("key1", "uint64"),
    ("path0", "int64"), ("unfinished", "int32[:]"), ("t_comp", "float64[:]"),
    ("xi_aux", "real[:]"), ("omega_noise", "float64"),
)


class ToolMissing(Exception):
    """numba-cuda or ptxas is not installed (exit status 2)."""


@dataclass
class Variant:
    label: str
    py_func: object
    signature: object
    options: dict  # compile options (fastmath, opt, debug, lineinfo, launch_bounds, max_registers)


@dataclass
class PtxCounts:
    f64_arith: int
    f64_cvt: int
    int64_mul: int
    u32_products: int


_OPCODE = re.compile(r"^\s+(?:@!?%p\d+\s+)?([a-z]+(?:\.[a-z0-9]+)*)", re.M)


def ptx_counts(ptx: str) -> PtxCounts:
    """Static counts of the PTX instructions described in the module docstring (item 3)."""
    f64_arith = f64_cvt = int64_mul = u32_products = 0
    for op in _OPCODE.findall(ptx):
        parts = op.split(".")
        if "f64" in parts:
            if parts[0] == "cvt":
                f64_cvt += 1
            elif parts[0] not in ("ld", "st", "mov", "ldu"):
                f64_arith += 1
        if parts[0] in ("mul", "mad") and ("s64" in parts or "u64" in parts) and "wide" not in parts:
            int64_mul += 1
        if op in ("mul.wide.u32", "mul.hi.u32", "mad.wide.u32", "mad.hi.u32"):
            u32_products += 1
    return PtxCounts(f64_arith, f64_cvt, int64_mul, u32_products)


@dataclass
class Usage:
    registers: int
    spill_stores: int
    spill_loads: int
    stack_frame: int
    callee_spills: int  # spill bytes (stores + loads) of non-inlined device functions


# -- occupancy --------------------------------------------------------------------------------
def warps_from_registers(registers: int, threads_per_block: int = THREADS_PER_BLOCK) -> int:
    """Resident warps per sm_90 SM allowed by the register file alone, for whole blocks."""
    warps_per_block = -(-threads_per_block // WARP_SIZE)
    per_warp = -(-max(registers, 1) * WARP_SIZE // REG_ALLOC_UNIT) * REG_ALLOC_UNIT
    blocks = (REGS_PER_SM // per_warp) // warps_per_block
    blocks = min(blocks, MAX_BLOCKS_PER_SM, MAX_WARPS_PER_SM // warps_per_block)
    return blocks * warps_per_block


# -- tools ------------------------------------------------------------------------------------
def find_ptxas() -> str:
    """ptxas of the nvidia-cuda-nvcc wheel of this environment, else the one on PATH."""
    with contextlib.suppress(ImportError, ValueError):
        spec = importlib.util.find_spec("nvidia.cuda_nvcc")
        if spec is not None and spec.submodule_search_locations:
            for location in spec.submodule_search_locations:
                candidate = Path(location) / "bin" / "ptxas"
                if candidate.is_file() and os.access(candidate, os.X_OK):
                    return str(candidate)
    found = shutil.which("ptxas")
    if found:
        return found
    raise ToolMissing("ptxas not found (pip package nvidia-cuda-nvcc-cu12)")


def tool_version(ptxas: str) -> str:
    out = subprocess.run([ptxas, "--version"], capture_output=True, text=True).stdout
    match = re.search(r"release [\d.]+, V([\d.]+)", out)
    return match.group(1) if match else "?"


def load_numba_cuda():
    """Import NVIDIA's numba-cuda (not Numba's deprecated built-in target) with the stub."""
    os.environ["NUMBA_ENABLE_CUDASIM"] = "0"
    try:
        import numba.cuda.dispatcher as cuda_dispatcher
        from numba import cuda
    except Exception as error:  # numba or its CUDA target missing or broken
        raise ToolMissing(f"numba.cuda cannot be imported ({type(error).__name__}: {error})") from error
    if getattr(cuda, "implementation", None) != "NVIDIA":
        raise ToolMissing("numba-cuda is not installed (numba.cuda is Numba's built-in target)")
    if not hasattr(cuda_dispatcher, "get_current_device"):
        raise ToolMissing("this numba-cuda has no numba.cuda.dispatcher.get_current_device to stub; "
                          "use the version pinned in benchmarks/cuda-tools.txt")
    # Device functions are compiled "for the current device": answer without a driver.
    cuda_dispatcher.get_current_device = lambda: types.SimpleNamespace(compute_capability=CC)
    return cuda


def package_version(name: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "?"


# -- kernels ----------------------------------------------------------------------------------
_OPTION_KEYS = ("fastmath", "opt", "debug", "lineinfo", "launch_bounds", "max_registers")
#: @cuda.jit's defaults (opt: NUMBA_OPT, 3 unless set); anything else is noted under the table.
DEFAULT_OPTIONS = {"fastmath": False, "opt": True, "debug": False, "lineinfo": False,
                   "launch_bounds": None, "max_registers": None}


def as_variant(label: str, kernel: object, signature: object) -> Variant:
    """A Python function, or a @cuda.jit dispatcher whose compile options are kept."""
    options: dict = {}
    py_func = kernel
    if hasattr(kernel, "py_func") and hasattr(kernel, "targetoptions"):
        py_func = kernel.py_func
        target = dict(kernel.targetoptions)
        options = {key: target[key] for key in _OPTION_KEYS if target.get(key) is not None}
        if target.get("link"):
            print(f"note: {label}: files linked with link= are not part of the measurement",
                  file=sys.stderr)
    return Variant(label, py_func, signature, options)


def current_advance_variants(backend, nt) -> list[Variant]:
    """The current code's advance kernel, float64 and float32 (no ``kernel_variants``)."""
    variants = []
    for precision in ("float64", "float32"):
        kernel = backend._kernels(precision).advance
        py_func = getattr(kernel, "py_func", kernel)
        names = tuple(inspect.signature(py_func).parameters)
        expected = tuple(name for name, _ in ADVANCE_ARGS)
        if names != expected:
            raise RuntimeError(
                "the advance kernel's arguments are not the ones this script knows "
                f"({', '.join(names)}); give the backend a kernel_variants() function")
        real = getattr(nt, precision)

        def numba_type(spec: str, real=real):
            base = spec.removesuffix("[:]")
            scalar = real if base == "real" else getattr(nt, base)
            return nt.Array(scalar, 1, "C") if spec.endswith("[:]") else scalar

        signature = tuple(numba_type(spec) for _, spec in ADVANCE_ARGS)
        variants.append(as_variant(f"advance {precision} (current)", kernel, signature))
    return variants


def in_ci_subset(label: str) -> bool:
    """The representative subset of ``--subset ci`` (``make cuda-compile-check CUDA_CHECK=ci``):
    every kernel kind of ``kernel_variants()`` (the label's first word), and within each kind
    every noise, oscillator, coupling, precision, step mode, family term set, additive channel
    and accumulator kind at least once, about a third of the kernels. A label it does not know
    (a kind added later) is kept, so a new kind is never left out."""
    kind, _, rest = label.partition(" ")
    parts = rest.split("/")
    if kind == "advance":
        # every noise x precision x step on the pendulum; each other oscillator and coupling
        # once (OU, float64, adaptive); every family term set and additive channel
        return parts[:2] == ["pendulum", "force"] or "+" in rest or (
            parts[2:5] == ["ou", "float64", "adaptive"])
    if kind == "pairs":
        return "+" in rest or parts[:3] == ["pendulum", "force", "ou"]
    if kind == "levels":  # the deepest, four members, of every KernelSpec it lists
        return rest.endswith("[L=4]")
    if kind == "tracked":
        return rest.endswith("[all]") or "/float64/adaptive/" in rest
    if kind == "accumulate":
        return rest.endswith("[all]") or (rest.endswith("float64") and "[" not in rest)
    return True  # init, joint (a few fast kernels), and any kind added later


def kernel_variants(backend, nt) -> list[Variant]:
    if hasattr(backend, "kernel_variants"):
        return [as_variant(str(label), kernel, signature)
                for label, kernel, signature in backend.kernel_variants()]
    return current_advance_variants(backend, nt)


# -- compile and assemble ---------------------------------------------------------------------
def compile_to_ptx(cuda, variant: Variant, lto: bool) -> str:
    options = {key: variant.options[key] for key in ("fastmath", "opt", "debug", "lineinfo",
                                                      "launch_bounds") if key in variant.options}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # performance hints of the typing pass
        if not lto:
            ptx, _ = cuda.compile_ptx(variant.py_func, variant.signature, cc=CC, **options)
            return ptx
        ltoir, _ = cuda.compile(variant.py_func, variant.signature, cc=CC, device=False,
                                abi="numba", output="ltoir", **options)
    from cuda.core import Linker, LinkerOptions, ObjectCode  # nvJitLink, no driver needed

    link_options = LinkerOptions(arch=ARCH, link_time_optimization=True, ptx=True,
                                 max_register_count=variant.options.get("max_registers"))
    linked = Linker(ObjectCode.from_ltoir(ltoir, name=variant.label), options=link_options).link("ptx")
    code = linked.code
    return code.decode() if isinstance(code, bytes) else code


_FRAME = re.compile(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads")


def parse_ptxas(log: str) -> dict[str, Usage]:
    """``ptxas -v`` output: the usage of each entry function (kernel), by mangled name."""
    entries: dict[str, Usage] = {}
    frames: dict[str, tuple[int, int, int]] = {}
    current_entry = None
    current_function = None
    for line in log.splitlines():
        if match := re.search(r"Compiling entry function '([^']+)'", line):
            current_entry = match.group(1)
            entries[current_entry] = Usage(0, 0, 0, 0, 0)
        elif match := re.search(r"Function properties for (\S+)", line):
            current_function = match.group(1)
        elif (match := _FRAME.search(line)) and current_function is not None:
            frames[current_function] = tuple(int(v) for v in match.groups())
            current_function = None
        elif (match := re.search(r"Used (\d+) registers", line)) and current_entry is not None:
            entries[current_entry].registers = int(match.group(1))
    callee_spills = sum(s + l for name, (_, s, l) in frames.items() if name not in entries)
    for name, usage in entries.items():
        usage.stack_frame, usage.spill_stores, usage.spill_loads = frames.get(name, (0, 0, 0))
        usage.callee_spills = callee_spills
    return entries


def assemble(ptxas: str, ptx: str, max_registers: int | None) -> tuple[dict[str, Usage], str]:
    with tempfile.TemporaryDirectory(prefix="cuda-registers-") as tmp:
        source = Path(tmp) / "kernel.ptx"
        source.write_text(ptx)
        command = [ptxas, f"-arch={ARCH}", "-v", "-o", str(Path(tmp) / "kernel.cubin"), str(source)]
        if max_registers:
            command.insert(1, f"-maxrregcount={int(max_registers)}")
        result = subprocess.run(command, capture_output=True, text=True)
    log = result.stdout + result.stderr
    if result.returncode != 0:
        raise RuntimeError(f"ptxas failed:\n{log}")
    return parse_ptxas(log), log


# -- output -----------------------------------------------------------------------------------
HEADER = ("| kernel | registers | spill stores (bytes) | spill loads (bytes) | stack frame (bytes) "
          f"| register limit on occupancy ({THREADS_PER_BLOCK}-thread blocks) "
          "| PTX f64 arith. | PTX f64 cvt | PTX 64-bit int mul | PTX mul.wide/hi.u32 |")
RULE = "|---|---:|---:|---:|---:|---|---:|---:|---:|---:|"


def row(label: str, usage: Usage, counts: PtxCounts | None = None) -> str:
    warps = warps_from_registers(usage.registers)
    share = 100.0 * warps / MAX_WARPS_PER_SM
    c = counts or PtxCounts(-1, -1, -1, -1)
    return (f"| {label} | {usage.registers} | {usage.spill_stores} | {usage.spill_loads} "
            f"| {usage.stack_frame} | {warps}/{MAX_WARPS_PER_SM} warps ({share:.1f}%) "
            f"| {c.f64_arith} | {c.f64_cvt} | {c.int64_mul} | {c.u32_products} |")


@contextlib.contextmanager
def source_at(ref: str | None):
    """Put ``src/`` (of the working tree, or of git revision ``ref``) first on sys.path."""
    if ref is None:
        if str(ROOT / "src") not in sys.path:
            sys.path.insert(0, str(ROOT / "src"))
        yield f"working tree ({ROOT / 'src'})"
        return
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref, "src"],
                             capture_output=True)
    if archive.returncode != 0:
        raise SystemExit(f"error: git archive {ref} failed: {archive.stderr.decode().strip()}")
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", f"{ref}^{{commit}}"],
                            capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="cuda-registers-src-") as tmp:
        with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
            tar.extractall(tmp, filter="data")
        sys.path.insert(0, str(Path(tmp) / "src"))
        yield f"git {ref} ({commit})"


#: Labels that name the same kernel under an older name: (old, new) substrings. The additive
#: OU channel was ``+additive_ou`` until the three additive channels became one (issue 33, item 5).
LABEL_RENAMES = (("+additive_ou+", "+additive_noise=ou+"),)

#: The modules that have held the CUDA backend, newest first: ``--ref`` of a revision before the
#: package's folders became its layers (81e8b64) finds it at the second.
BACKEND_MODULES = ("stochpend.engine.cuda", "stochpend._backends.cuda")


@dataclass(frozen=True)
class TableRow:
    """One kernel's row of a table this script wrote: registers, spills (bytes), or failed."""

    registers: int
    spill_stores: int
    spill_loads: int
    failed: bool = False


def read_table(text: str) -> dict[str, TableRow]:
    """The kernels of a table this script wrote, by label (:data:`LABEL_RENAMES` applied)."""
    rows: dict[str, TableRow] = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("| ") or len(cells) < 4 or cells[0] == "kernel":
            continue
        label = cells[0]
        for old, new in LABEL_RENAMES:
            label = label.replace(old, new)
        if cells[1] == "compile failed":
            rows[label] = TableRow(0, 0, 0, failed=True)
            continue
        try:
            rows[label] = TableRow(int(cells[1]), int(cells[2]), int(cells[3]))
        except ValueError:
            continue
    return rows


def compare(before: dict[str, TableRow], after: dict[str, TableRow]) -> tuple[list[str], bool]:
    """The lines of a comparison of two tables (a summary, then a table of every kernel in both
    whose registers changed, largest rise first) and whether AFTER keeps issue 33's criterion:
    no kernel in both with more registers, no kernel of AFTER that spills or failed."""
    common = [label for label in before if label in after and not before[label].failed and not after[label].failed]
    changed = [label for label in common if after[label].registers != before[label].registers]
    more = [label for label in changed if after[label].registers > before[label].registers]
    spilling = [label for label, r in after.items() if r.spill_stores or r.spill_loads]
    failed = [label for label, r in after.items() if r.failed]
    lines = [f"{len(before)} kernels before, {len(after)} after, {len(common)} in both: "
             f"{len(common) - len(changed)} the same, {len(changed) - len(more)} fewer registers, "
             f"{len(more)} more; {len(spilling)} spill after, {len(failed)} failed after."]
    if changed:
        lines += ["", "| kernel | before | after | change | occupancy limit before | after |",
                  "|---|---:|---:|---:|---|---|"]
        for label in sorted(changed, key=lambda k: (before[k].registers - after[k].registers, k)):
            b, a = before[label].registers, after[label].registers
            lines.append(f"| {label} | {b} | {a} | {a - b:+d} | {warps_from_registers(b)}/{MAX_WARPS_PER_SM} "
                         f"warps | {warps_from_registers(a)}/{MAX_WARPS_PER_SM} warps |")
    lines += [f"spills after: {label}" for label in spilling] + [f"failed after: {label}" for label in failed]
    return lines, not (more or spilling or failed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="also write the table (Markdown) to this file")
    parser.add_argument("--filter", default=None, metavar="SUBSTRING",
                        help="compile only the kernels whose label contains SUBSTRING")
    parser.add_argument("--lto", action="store_true",
                        help="link with nvJitLink LTO first, as a launched @cuda.jit kernel is")
    parser.add_argument("--ref", default=None, metavar="GIT_REF",
                        help="measure src/ as committed at GIT_REF instead of the working tree")
    parser.add_argument("--ptx-dir", type=Path, default=None,
                        help="also keep each kernel's PTX in this directory")
    parser.add_argument("--subset", choices=("all", "ci"), default="all",
                        help="all kernels (default), or ci: every kernel kind, about a third of them")
    parser.add_argument("--compare", nargs=2, type=Path, default=None, metavar=("BEFORE", "AFTER"),
                        help="compile nothing: compare two tables written with --out (exit 1 on a "
                             "kernel with more registers, a spill or a failure in AFTER)")
    args = parser.parse_args(argv)

    if args.compare is not None:
        try:
            before, after = (read_table(path.read_text()) for path in args.compare)
        except (OSError, UnicodeDecodeError) as error:
            print(f"error: --compare: {error}", file=sys.stderr)
            return 2
        if not before or not after:
            empty = args.compare[0] if not before else args.compare[1]
            print(f"error: --compare: {empty} holds no table of kernels", file=sys.stderr)
            return 2
        lines, kept = compare(before, after)
        print("\n".join(lines))
        return 0 if kept else 1

    try:
        cuda = load_numba_cuda()
        ptxas = find_ptxas()
        if args.lto:
            try:
                importlib.import_module("cuda.core")  # nvJitLink's linker
            except ImportError as error:
                raise ToolMissing(f"cuda.core is not installed, --lto needs it ({error})") from error
    except ToolMissing as error:
        print(f"error: {error}; {INSTALL_HINT}", file=sys.stderr)
        return 2
    from numba import types as nt

    with source_at(args.ref) as source:
        backend = None
        for module in BACKEND_MODULES:
            try:
                backend = importlib.import_module(module)
                break
            except ModuleNotFoundError as error:
                if error.name is None or not module.startswith(error.name):
                    print(f"error: cannot import {module} from {source}: {error}", file=sys.stderr)
                    return 1
            except Exception as error:
                print(f"error: cannot import {module} from {source}: "
                      f"{type(error).__name__}: {error}", file=sys.stderr)
                return 1
        if backend is None:
            print(f"error: none of {', '.join(BACKEND_MODULES)} in {source}", file=sys.stderr)
            return 1

        variants = kernel_variants(backend, nt)
        if args.filter is not None:
            variants = [v for v in variants if args.filter in v.label]
        if args.subset == "ci":
            variants = [v for v in variants if in_ci_subset(v.label)]
        if not variants:
            print(f"error: no kernel label contains {args.filter!r}", file=sys.stderr)
            return 2

        mode = ("NVVM LTO-IR -> nvJitLink (LTO) -> PTX -> ptxas" if args.lto
                else "compile_ptx -> ptxas")
        lines = [
            f"CUDA kernels for {ARCH} (compiled offline, no GPU): {mode}; source: {source}; "
            f"numba {package_version('numba')}, numba-cuda {package_version('numba-cuda')}, "
            f"ptxas {tool_version(ptxas)}"
            + (f", nvJitLink {package_version('nvidia-nvjitlink-cu12')}" if args.lto else "")
            + ".",
            "",
            HEADER,
            RULE,
        ]
        notes = []
        failed = False
        started_all = time.perf_counter()
        for variant in variants:
            start = time.perf_counter()
            try:
                ptx = compile_to_ptx(cuda, variant, args.lto)
                compiled = time.perf_counter()
                entries, _ = assemble(ptxas, ptx, variant.options.get("max_registers"))
            except Exception as error:
                failed = True
                print(f"error: {variant.label}: {type(error).__name__}: {error}", file=sys.stderr)
                lines.append(f"| {variant.label} | compile failed | | | | | | | | |")
                continue
            done = time.perf_counter()
            print(f"{variant.label}: compiled in {compiled - start:.1f} s, ptxas {done - compiled:.1f} s",
                  file=sys.stderr)
            if args.ptx_dir is not None:
                args.ptx_dir.mkdir(parents=True, exist_ok=True)
                name = re.sub(r"[^A-Za-z0-9._-]+", "_", variant.label).strip("_")
                (args.ptx_dir / f"{name}.ptx").write_text(ptx)
            for number, usage in enumerate(entries.values()):
                label = variant.label if len(entries) == 1 else f"{variant.label} [{number}]"
                lines.append(row(label, usage, ptx_counts(ptx)))
                if usage.callee_spills:
                    notes.append(f"{label}: the non-inlined device functions it calls spill "
                                 f"{usage.callee_spills} bytes (stores + loads) more.")
            unusual = {k: v for k, v in variant.options.items() if v != DEFAULT_OPTIONS.get(k)}
            if unusual:
                shown = ", ".join(f"{k}={v}" for k, v in sorted(unusual.items()))
                notes.append(f"{variant.label}: compiled with {shown} (from its @cuda.jit).")
        if notes:
            lines += [""] + notes
    n_failed = sum(1 for line in lines if "| compile failed |" in line)
    print(f"{len(variants)} kernels ({'every kernel kind, the CI subset' if args.subset == 'ci' else 'all'}): "
          f"{len(variants) - n_failed} compiled for {ARCH}, {n_failed} failed, in "
          f"{time.perf_counter() - started_all:.0f} s", file=sys.stderr)
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
