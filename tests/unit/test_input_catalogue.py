"""The input catalogue: bad input of every kind, for every command and the Python API.

Each command-line case must end with exit code 2 and exactly one line that names the
parameter and what is accepted, no traceback, and nothing left behind in the working
directory. Each API case must raise one ``ValueError`` line naming the parameter. No case
starts a simulation: the runners are replaced by a guard that fails the test if reached.
"""

from __future__ import annotations

import pathlib
from unittest import mock

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import stochpend
from stochpend.cli import app

FAST = ["--paths", "10", "--t-max", "1"]

#: (id, arguments, needles that the one line must contain: the parameter, a fragment of what
#: is accepted). "{d}" is the case's temporary directory.
CLI_CASES = [
    # simulate: sizes, resources, numbers, names, contradictions, files
    ("simulate-paths-1e15-digits", ["simulate", "--paths", "1000000000000000"],
     ["--paths 1000000000000000", "path-steps", "--max-path-steps"]),
    ("simulate-paths-1e15-scientific", ["simulate", "--paths", "1e15"], ["--paths 1000000000000000", "path-steps"]),
    ("simulate-paths-not-whole", ["simulate", "--paths", "1e15.5"], ["--paths '1e15.5'", "an integer"]),
    ("simulate-paths-word", ["simulate", "--paths", "many"], ["--paths 'many'", "an integer"]),
    ("simulate-paths-zero", ["simulate", "--paths", "0", "--t-max", "1"], ["--paths 0", "integer in [1"]),
    ("simulate-hist-bins-1e9", ["simulate", "--hist-bins", "1000000000"], ["--hist-bins 1000000000", "of memory"]),
    ("simulate-t-max-1e300", ["simulate", "--t-max", "1e300", "--paths", "100"], ["--t-max 1e+300", "path-steps"]),
    ("simulate-t-max-inf", ["simulate", "--paths", "10", "--t-max", "inf"], ["--t-max inf", "finite number in [1e-300"]),
    ("simulate-times-and-n-times", ["simulate", *FAST, "--times", "1,2", "--n-times", "5"], ["--n-times 5", "not both"]),
    ("simulate-times-decreasing", ["simulate", *FAST, "--times", "0.5,0.1"], ["--times ", "increasing"]),
    ("simulate-times-beyond-t-max", ["simulate", *FAST, "--times", "0.5,2"], ["--times ", "[0, t_max]"]),
    ("simulate-n-times-1e7", ["simulate", *FAST, "--n-times", "1e7"], ["--n-times 10000000", "1000000"]),
    ("simulate-D-nan", ["simulate", *FAST, "--D", "nan"], ["--D nan", ">= 0"]),
    ("simulate-D-word", ["simulate", *FAST, "--D", "strong"], ["--D 'strong'", "a number"]),
    ("simulate-tau-minus-inf", ["simulate", *FAST, "--tau", "-inf"], ["--tau -inf", "> 0"]),
    ("simulate-omega-1e200", ["simulate", *FAST, "--omega", "1e200"], ["--omega 1e+200", "1e+150"]),
    ("simulate-noise-unknown", ["simulate", *FAST, "--noise", "pink"], ["--noise 'pink'", "dichotomous"]),
    ("simulate-potential-unknown", ["simulate", *FAST, "--potential", "duffing"], ["--potential 'duffing'", "pendulum"]),
    ("simulate-pendulum-position", ["simulate", *FAST, "--coupling", "position"], ["--coupling 'position'", "force"]),
    ("simulate-power-n-huge", ["simulate", *FAST, "--potential", "power", "--n", "1e5"], ["--n 100000", "1000]"]),
    ("simulate-seed-negative", ["simulate", *FAST, "--seed", "-1"], ["--seed -1", "2**64"]),
    ("simulate-seed-1e20", ["simulate", *FAST, "--seed", "1e20"], ["--seed 100000000000000000000", "2**64"]),
    ("simulate-theta0-word", ["simulate", *FAST, "--theta0", "north"], ["--theta0 'north'", "uniform"]),
    ("simulate-fixed-point", ["simulate", *FAST, "--theta0", "0", "--Omega0", "0"], ["--theta0 0.0", "fixed point"]),
    ("simulate-omega-noise-not-harmonic", ["simulate", *FAST, "--omega-noise", "2"], ["--omega-noise 2.0", "harmonic"]),
    ("simulate-backend-unknown", ["simulate", *FAST, "--backend", "tpu"], ["--backend 'tpu'", "cpu"]),
    ("simulate-precision-unknown", ["simulate", *FAST, "--precision", "float16"], ["--precision 'float16'", "float64"]),
    ("simulate-float32-on-cpu", ["simulate", *FAST, "--precision", "float32"], ["--precision 'float32'", "CUDA"]),
    ("simulate-threads-zero", ["simulate", *FAST, "--threads", "0"], ["--threads 0", "integer in [1"]),
    ("simulate-max-path-steps-negative", ["simulate", *FAST, "--max-path-steps", "-5"],
     ["--max-path-steps -5.0", "> 0"]),
    ("simulate-checkpoint-every-alone", ["simulate", *FAST, "--checkpoint-every", "5m"],
     ["--checkpoint-every '5m'", "--checkpoint"]),
    ("simulate-checkpoint-every-word",
     ["simulate", *FAST, "--checkpoint", "{d}/run.ckpt", "--checkpoint-every", "soon"],
     ["--checkpoint-every 'soon'", "duration"]),
    ("simulate-out-exists", ["simulate", *FAST, "--out", "{d}/existing.nc"], ["--out ", "--overwrite"]),
    ("simulate-out-no-directory", ["simulate", *FAST, "--out", "{d}/missing/run.nc"], ["--out ", "does not exist"]),
    ("simulate-unknown-option", ["simulate", *FAST, "--frobnicate", "3"], ["--frobnicate", "no such option"]),
    # the walk-through's typos and names (new-user-walkthrough-turn4.md G2, M13)
    ("simulate-out-directory", ["simulate", *FAST, "--out", "{d}"], ["--out ", "it is a directory, not a file"]),
    ("simulate-out-directory-overwrite", ["simulate", *FAST, "--out", "{d}", "--overwrite"],
     ["--out ", "it is a directory, not a file"]),
    ("simulate-option-typo", ["simulate", "--pahts", "10"], ["--pahts", "Possible options: --bias-paths, --paths"]),
    ("command-typo", ["simulat"], ["'simulat'", "Did you mean 'simulate'?"]),
    ("simulate-potential-typo", ["simulate", "--potentail", "x"], ["--potentail", "--potential"]),
    ("simulate-paths-10k", ["simulate", "--paths", "10k"], ["--paths '10k'", "an integer"]),
    ("simulate-noise-capitals", ["simulate", *FAST, "--noise", "OU"], ["--noise 'OU'", "lower case: 'ou'"]),
    ("reproduce-unknown-figure", ["reproduce", "fig5", "--quick", "--out", "{d}/r5"], ["figure='fig5'", "fig1"]),
    # show: foreign, damaged and missing files
    ("show-text-file", ["show", "{d}/notes.txt"], ["path=", "NetCDF"]),
    ("show-truncated-netcdf", ["show", "{d}/truncated.nc"], ["path=", "NetCDF"]),
    ("show-png", ["show", "{d}/image.png"], ["path=", "NetCDF"]),
    ("show-foreign-netcdf", ["show", "{d}/foreign.nc"], ["path=", "not a file stochpend writes"]),
    ("show-missing-file", ["show", "{d}/nothing.nc"], ["path=", "no such file"]),
    ("show-directory", ["show", "{d}"], ["path=", "directory"]),
    ("show-no-argument", ["show"], ["'path'", "missing"]),
    ("show-rows-zero", ["show", "{d}/foreign.nc", "--rows", "0"], ["--rows 0", ">= 1"]),
    # sweep: malformed and foreign specs, bad and huge sets
    ("sweep-malformed-toml", ["sweep", "{d}/broken.toml"], ["sweep=", "TOML"]),
    ("sweep-text-file", ["sweep", "{d}/notes.txt"], ["sweep=", "TOML"]),
    ("sweep-missing-file", ["sweep", "{d}/nothing.toml"], ["sweep=", "no such file"]),
    ("sweep-set-paths-zero", ["sweep", "{d}/paths0.toml"], ["paths=0", "integer in [1"]),
    ("sweep-set-huge", ["sweep", "{d}/huge.toml"], ["paths=1000000000000000", "path-steps", "set 1 of 2"]),
    ("sweep-workers-zero", ["sweep", "{d}/small.toml", "--workers", "0"], ["--workers 0", "an integer in [1, "]),
    ("sweep-workers-huge", ["sweep", "{d}/small.toml", "--workers", "1e6"], ["--workers 1000000", "this machine's CPUs"]),
    ("sweep-out-exists", ["sweep", "{d}/small.toml", "--out", "{d}/existing.nc"], ["--out ", "--overwrite"]),
    # resume: anything but a checkpoint
    ("resume-netcdf", ["resume", "{d}/foreign.nc"], ["checkpoint=", "not a stochpend checkpoint"]),
    ("resume-empty-file", ["resume", "{d}/empty.ckpt"], ["checkpoint=", "checkpoint"]),
    ("resume-png", ["resume", "{d}/image.png"], ["checkpoint=", "not a stochpend checkpoint"]),
    ("resume-missing-file", ["resume", "{d}/nothing.ckpt"], ["checkpoint=", "no such file"]),
    ("resume-threads-word", ["resume", "{d}/empty.ckpt", "--threads", "two"], ["--threads 'two'", "an integer"]),
    # theory, bfpe, reduced, reproduce, scaling
    ("theory-t-negative", ["theory", "--t", "-5"], ["--time -5.0", ">= 0"]),
    ("theory-noise-unsupported", ["theory", "--noise", "dichotomous"], ["--noise 'dichotomous'", "ou"]),
    ("theory-tau-nan", ["theory", "--tau", "nan"], ["--tau nan", "> 0"]),
    ("bfpe-n-cells-1e12", ["bfpe", "--n-cells", "1e12"], ["--n-cells 1000000000000", "10000000]"]),
    ("bfpe-steps-per-decade-not-whole", ["bfpe", "--steps-per-decade", "1e2.5"],
     ["--steps-per-decade '1e2.5'", "an integer"]),
    ("bfpe-t-max-1e300", ["bfpe", "--t-max", "1e300"], ["--t-max 1e+300", "t_c"]),
    ("bfpe-D-zero", ["bfpe", "--D", "0"], ["--D 0.0", "> 0"]),
    ("bfpe-out-exists", ["bfpe", "--out", "{d}/existing.nc"], ["--out ", "--overwrite"]),
    ("reduced-order-unknown", ["reduced", "--order", "third"], ["--order 'third'", "asymptotic"]),
    ("reduced-times-and-n-times", ["reduced", "--times", "1,2", "--n-times", "5"], ["--n-times 5", "not both"]),
    ("reduced-E0-negative", ["reduced", "--E0", "-1"], ["--E0 -1.0", ">= 0"]),
    ("reduced-paths-1e15", ["reduced", "--paths", "1e15"], ["--paths 1000000000000000", "of memory"]),
    ("reproduce-figure-unknown", ["reproduce", "fig9", "--out", "{d}/rep"], ["figure='fig9'", "fig1"]),
    ("reproduce-paths-one", ["reproduce", "--paths", "1", "--out", "{d}/rep"], ["--paths 1", ">= 2"]),
    ("reproduce-paths-1e15", ["reproduce", "--paths", "1e15", "--out", "{d}/rep"],
     ["--paths 1000000000000000", "path-steps"]),
    ("reproduce-t-max-nan", ["reproduce", "--t-max", "nan", "--out", "{d}/rep"], ["--t-max nan", "> 0.1"]),
    ("scaling-n-one", ["scaling", "--n", "1"], ["--n 1", "[2, 1000]"]),
    ("scaling-n-word", ["scaling", "--n", "two"], ["--n 'two'", "an integer"]),
    ("unknown-command", ["frobnicate"], ["'frobnicate'", "no such command"]),
]


@pytest.fixture
def files(tmp_path: pathlib.Path) -> pathlib.Path:
    """A directory of foreign, damaged and malformed inputs."""
    (tmp_path / "notes.txt").write_text("this is not a results file\n")
    (tmp_path / "image.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))
    (tmp_path / "empty.ckpt").write_bytes(b"")
    xr.Dataset({"a": ("x", np.arange(4.0))}).to_netcdf(tmp_path / "foreign.nc", engine="h5netcdf")
    data = (tmp_path / "foreign.nc").read_bytes()
    (tmp_path / "truncated.nc").write_bytes(data[: len(data) // 2])
    (tmp_path / "existing.nc").write_bytes(b"keep me")
    (tmp_path / "broken.toml").write_text("[base\nnoise = 'ou'\n")
    (tmp_path / "paths0.toml").write_text("[base]\npaths = 0\nt_max = 1.0\n[grid]\nD = [1.0, 2.0]\n")
    (tmp_path / "huge.toml").write_text("[base]\npaths = 1e15\nt_max = 1000.0\n[grid]\nD = [1.0, 2.0]\n")
    (tmp_path / "small.toml").write_text("[base]\npaths = 10\nt_max = 1.0\nn_times = 2\n[grid]\nD = [1.0, 2.0]\n")
    return tmp_path


def _listing(root: pathlib.Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else b"<dir>") for p in root.rglob("*")}


def _no_work(*args, **kwargs):
    raise AssertionError("a refused input started work")


@pytest.fixture(autouse=True)
def no_simulation():
    """Every runner replaced: a case that got past validation fails instead of running."""
    targets = ["stochpend.runs.simulate.run", "stochpend.runs.lifecycle.execute", "stochpend.engine.runner.run_batches",
               "stochpend.runs.checkpoint.run_checkpointed",
               "stochpend.sweep.sweep", "stochpend.runs.reduced._run_chunk", "stochpend.paper.reproduce._simulate"]
    patches = [mock.patch(t, _no_work) for t in targets]
    for p in patches:
        p.start()
    yield
    for p in patches:
        p.stop()


@pytest.mark.parametrize("args,needles", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES])
def test_cli_refuses_in_one_line(files, args, needles):
    args = [a.format(d=files) for a in args]
    before = _listing(files)
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line, got: {result.output!r}"
    assert lines[0].startswith("error: "), lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert _listing(files) == before, "a file was created, changed or removed"


def _api_cases(d: pathlib.Path) -> list[tuple[str, object, str]]:
    from stochpend import io, sweep, theory
    from stochpend.model.settings import SimulationConfig
    from stochpend.paper import reproduce
    from stochpend.runs import checkpoint, reduced

    return [
        ("simulate-paths-1e15", lambda: stochpend.simulate(paths=10**15), "paths="),
        ("simulate-hist-bins-1e9", lambda: stochpend.simulate(hist_bins=10**9), "hist_bins="),
        ("simulate-hist-bins-10**400", lambda: stochpend.simulate(paths=10, t_max=1.0, hist_bins=10**400),
         "hist_bins="),
        ("simulate-t-max-1e300", lambda: stochpend.simulate(paths=100, t_max=1e300), "t_max="),
        ("simulate-chunk-paths-1e12",
         lambda: stochpend.simulate(paths=10**13, t_max=1e-4, n_times=1, chunk_paths=10**12), "chunk_paths="),
        ("simulate-potential-list", lambda: stochpend.simulate(paths=10, potential=["pendulum"]), "potential="),
        ("simulate-times-complex", lambda: stochpend.simulate(paths=10, t_max=1.0, times=[1 + 2j]), "times="),
        ("simulate-D-huge-int", lambda: stochpend.simulate(paths=10, D=10**400), "D="),
        ("simulate-max-path-steps-word", lambda: stochpend.simulate(paths=10, max_path_steps="lots"),
         "max_path_steps="),
        ("simulate-threads-float", lambda: stochpend.simulate(paths=10, t_max=1.0, threads=1.5), "threads="),
        ("build-hist-E-max-word", lambda: SimulationConfig.build(hist_E_max="high"), "hist_E_max="),
        ("build-n-times-1e9", lambda: SimulationConfig.build(n_times=10**9), "n_times="),
        ("build-power-n-huge", lambda: SimulationConfig.build(potential="power", power_n=10**30), "power_n="),
        ("bfpe-tau-1e40", lambda: theory.solve_bfpe(D=1.0, tau=1e40, t_max=1e5), "tau="),
        ("bfpe-n-cells-1e12", lambda: theory.solve_bfpe(D=1.0, tau=0.1, t_max=1e5, n_cells=10**12), "n_cells="),
        ("bfpe-D-tiny", lambda: theory.solve_bfpe(D=5e-324, tau=0.1, t_max=1e5), "D="),
        ("reduced-order-unknown", lambda: reduced.simulate_reduced("third", D=1.0, tau=1.0), "order="),
        ("reduced-paths-1e15", lambda: reduced.simulate_reduced("asymptotic", D=1.0, tau=1.0, paths=10**15),
         "paths="),
        ("reduced-sample-paths-1e12", lambda: reduced.sample_reduced("first", D=1.0, tau=1.0, paths=10**12,
                                                                     n_times=1), "paths="),
        ("open-results-png", lambda: io.open_results(d / "image.png"), "path="),
        ("open-results-truncated", lambda: io.open_results(d / "truncated.nc"), "path="),
        ("load-spec-paths-zero", lambda: sweep.load_spec({"base": {"paths": 0}, "grid": {"D": [1.0]}}), "paths="),
        ("checkpoint-read-empty", lambda: checkpoint.read(d / "empty.ckpt"), "checkpoint="),
        ("reproduce-figure-unknown", lambda: reproduce.reproduce(["fig9"], out=d / "rep"), "figure="),
        ("reproduce-t-max-1e12", lambda: reproduce.reproduce(["fig1"], t_max=1e12, out=d / "rep"), "t_max="),
    ]


API_IDS = [c[0] for c in _api_cases(pathlib.Path("."))]


@pytest.mark.parametrize("index", range(len(API_IDS)), ids=API_IDS)
def test_api_refuses_in_one_line(files, index):
    _, call, needle = _api_cases(files)[index]
    before = _listing(files)
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert "\n" not in message, message
    assert needle in message and "is not accepted" in message, message
    assert _listing(files) == before, "a file was created, changed or removed"


def test_catalogue_size():
    assert len(CLI_CASES) + len(API_IDS) >= 40
