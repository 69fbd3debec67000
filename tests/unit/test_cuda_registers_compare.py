"""benchmarks/cuda_registers.py --compare: issue 33's "no kernel with more registers, no spills"
read from two tables the script wrote, without compiling anything."""

from __future__ import annotations

from benchmarks.cuda_registers import HEADER, RULE, TableRow, Usage, compare, main, read_table, row


def _table(*rows: tuple[str, int, int]) -> str:
    """A table as the script writes it: (label, registers, spilled bytes) per kernel."""
    lines = ["CUDA kernels for sm_90 (compiled offline, no GPU): test.", "", HEADER, RULE]
    for label, registers, spilled in rows:
        usage = Usage(registers=registers, spill_stores=spilled, spill_loads=spilled, stack_frame=40,
                      callee_spills=0)
        lines.append(row(label, usage))
    return "\n".join(lines) + "\n"


BEFORE = _table(("advance pendulum/force/ou/float64/adaptive/libm", 72, 0),
                ("pairs pendulum/force/white/float64/fixed/libm", 64, 0),
                ("advance pendulum/force/white/float64/adaptive/libm+additive_ou+damping", 88, 0),
                ("advance gone/float64", 50, 0))


def test_the_table_is_read_back_by_label_with_the_renamed_channel():
    rows = read_table(BEFORE)
    assert rows["pairs pendulum/force/white/float64/fixed/libm"] == TableRow(64, 0, 0)
    # The additive OU channel's old label reads as its new one, so the two tables meet.
    assert rows["advance pendulum/force/white/float64/adaptive/libm+additive_noise=ou+damping"].registers == 88
    assert len(rows) == 4


def test_one_register_more_in_one_kernel_breaks_the_criterion():
    after = _table(("advance pendulum/force/ou/float64/adaptive/libm", 70, 0),
                   ("pairs pendulum/force/white/float64/fixed/libm", 65, 0),
                   ("advance pendulum/force/white/float64/adaptive/libm+additive_noise=ou+damping", 88, 0),
                   ("advance new/float64", 200, 0))
    lines, kept = compare(read_table(BEFORE), read_table(after))
    assert not kept
    assert lines[0].startswith("4 kernels before, 4 after, 3 in both: 1 the same, 1 fewer registers, 1 more;")
    # Largest rise first; a kernel only in one table is not compared.
    changes = [line for line in lines if line.startswith("| ") and "kernel" not in line]
    assert changes[0].startswith("| pairs pendulum/force/white/float64/fixed/libm | 64 | 65 | +1 |")
    assert changes[1].startswith("| advance pendulum/force/ou/float64/adaptive/libm | 72 | 70 | -2 |")
    assert not any("new/float64" in line or "gone/float64" in line for line in lines)


def test_fewer_registers_keep_it_and_a_spill_or_a_failure_breaks_it(tmp_path):
    fewer = _table(("advance pendulum/force/ou/float64/adaptive/libm", 72, 0),
                   ("pairs pendulum/force/white/float64/fixed/libm", 60, 0))
    assert compare(read_table(BEFORE), read_table(fewer))[1]
    spilled = _table(("advance pendulum/force/ou/float64/adaptive/libm", 72, 0),
                     ("pairs pendulum/force/white/float64/fixed/libm", 60, 8))
    lines, kept = compare(read_table(BEFORE), read_table(spilled))
    assert not kept and "spills after: pairs pendulum/force/white/float64/fixed/libm" in lines
    failed = fewer + "| advance pendulum/force/white/float32/fixed/libm | compile failed | | | | | | | | |\n"
    lines, kept = compare(read_table(BEFORE), read_table(failed))
    assert not kept and "failed after: advance pendulum/force/white/float32/fixed/libm" in lines

    # The command's exit status: 0 kept, 1 broken, 2 a file that holds no table.
    paths = {}
    for name, text in (("before", BEFORE), ("fewer", fewer), ("spilled", spilled), ("empty", "no table\n")):
        paths[name] = tmp_path / f"{name}.md"
        paths[name].write_text(text)
    assert main(["--compare", str(paths["before"]), str(paths["fewer"])]) == 0
    assert main(["--compare", str(paths["before"]), str(paths["spilled"])]) == 1
    assert main(["--compare", str(paths["before"]), str(paths["empty"])]) == 2
    assert main(["--compare", str(paths["before"]), str(tmp_path / "missing.md")]) == 2
