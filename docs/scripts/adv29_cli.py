"""adv29: cheap CLI cases (seconds each). Writes odd inputs into a folder and runs
`avard analyze` / `avard explain` on each, printing exit status and the last lines.

    .venv/bin/python docs/scripts/adv29_cli.py OUTDIR [CASE ...]

A case passes when avard either gives a result or ends with one line and exit status 2; a
traceback, another exit status, or a hang (60 s) is printed as such.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

AVARD = str(Path(sys.executable).with_name("avard"))


def npz(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


def cases(d: Path) -> dict[str, list[str]]:
    rng = np.random.default_rng(29)
    n = 36000
    acc = rng.standard_normal((n, 2)) * 5e-4
    out: dict[str, list[str]] = {}

    def add(name, path, *extra, cmd="analyze"):
        out[name] = [cmd, str(path), *extra]

    add(
        "inf",
        npz(d / "inf.npz", accel=np.where(np.arange(n)[:, None] == 500, np.inf, acc), rate_hz=10.0),
    )
    add("huge", npz(d / "huge.npz", accel=acc * 1e200, rate_hz=10.0))
    add("huge_offset", npz(d / "huge_offset.npz", accel=acc + 1e12, rate_hz=10.0))
    add("tiny_offset_noise", npz(d / "tiny.npz", accel=acc * 1e-200, rate_hz=10.0))
    add("const", npz(d / "const.npz", accel=np.full((n, 2), 9.81), rate_hz=10.0))
    half = acc.copy()
    half[: n // 2, 0] = 0.0
    add("const_half", npz(d / "const_half.npz", accel=half, rate_hz=10.0))
    for m in (1, 2, 5, 20, 100, 300):
        add(f"len{m}", npz(d / f"len{m}.npz", accel=acc[:m], rate_hz=10.0))
    add("len0", npz(d / "len0.npz", accel=np.zeros((0, 2)), rate_hz=10.0))
    add("cols0", npz(d / "cols0.npz", accel=np.zeros((n, 0)), rate_hz=10.0))
    add("3d", npz(d / "3d.npz", accel=np.zeros((10, 2, 2)), rate_hz=10.0))
    add("int_accel", npz(d / "int.npz", accel=(acc * 1e6).astype(np.int64), rate_hz=10.0))
    add("complex", npz(d / "complex.npz", accel=acc.astype(complex), rate_hz=10.0))
    add("str_rate", npz(d / "str_rate.npz", accel=acc, rate_hz=np.array("10")))
    add("arr_rate", npz(d / "arr_rate.npz", accel=acc, rate_hz=np.array([10.0, 20.0])))
    add("bool_accel", npz(d / "bool.npz", accel=acc > 0, rate_hz=10.0))
    add(
        "object", npz(d / "object.npz", accel=np.array([[1, "a"]] * 10, dtype=object), rate_hz=10.0)
    )
    temp = np.full(n, np.nan)
    temp[::10] = 22.0 + np.round(rng.standard_normal(n // 10) * 0.1 / 0.0625) * 0.0625
    add(
        "temp_short",
        npz(d / "temp_short.npz", accel=acc, rate_hz=10.0, temperature_c=temp[: n // 2]),
        cmd="explain",
    )
    add(
        "temp_names_mismatch",
        npz(
            d / "temp_names.npz",
            accel=acc,
            rate_hz=10.0,
            temperature_c=temp,
            temperature_names=np.array(["a", "b"]),
        ),
        cmd="explain",
    )
    add(
        "temp_dup_names",
        npz(
            d / "temp_dup.npz",
            accel=acc,
            rate_hz=10.0,
            temperature_c=np.column_stack([temp, temp]),
            temperature_names=np.array(["a", "a"]),
        ),
        cmd="explain",
    )
    add(
        "temp_allnan",
        npz(d / "temp_nan.npz", accel=acc, rate_hz=10.0, temperature_c=np.full(n, np.nan)),
        cmd="explain",
    )
    add(
        "temp_inf",
        npz(
            d / "temp_inf.npz",
            accel=acc,
            rate_hz=10.0,
            temperature_c=np.where(np.arange(n) == 1000, np.inf, temp),
        ),
        cmd="explain",
    )
    add(
        "temp_kelvin",
        npz(d / "temp_k.npz", accel=acc, rate_hz=10.0, temperature_c=temp + 273.15),
        cmd="explain",
    )
    add(
        "axes_mismatch",
        npz(d / "axes.npz", accel=acc, rate_hz=10.0, axes=np.array(["x", "y", "z"])),
    )
    add("axes_dup", npz(d / "axes_dup.npz", accel=acc, rate_hz=10.0, axes=np.array(["x", "x"])))
    # CSVs
    t = np.arange(n) / 10.0

    def csv(name, header, rows, fmt="%.9g", sep=","):
        p = d / name
        with open(p, "w", encoding="utf-8") as f:
            f.write(header + "\n")
            np.savetxt(f, rows, fmt=fmt, delimiter=sep)
        return p

    def body(bad_row=None, bad="", sep=","):
        out_rows = []
        for i, (a, b, c) in enumerate(zip(t, acc[:, 0], acc[:, 1], strict=True)):
            out_rows.append(f"{a},{b}{bad}" if i == bad_row else f"{a},{b},{c}")
        return "\n".join(out_rows)

    add("csv_ok", csv("ok.csv", "t,x,y", np.column_stack([t, acc])))
    add("csv_dup_header", csv("dup.csv", "t,x,x", np.column_stack([t, acc])))
    add("csv_empty_name", csv("empty.csv", "t,,y", np.column_stack([t, acc])))
    add("csv_only_t", csv("only_t.csv", "t", t[:, None]))
    add("csv_only_temp", csv("only_temp.csv", "t,temp_plate", np.column_stack([t, t * 0 + 22])))
    tr = t.copy()
    tr[n // 2 :] = tr[n // 2 :] - 0.05  # a 0.5 spacing clock step back... makes t repeat-ish
    add(
        "csv_rate_change",
        csv(
            "rate_change.csv",
            "t,x,y",
            np.column_stack(
                [
                    np.concatenate(
                        [t[: n // 2], t[n // 2 - 1] + 0.05 * np.arange(1, n - n // 2 + 1)]
                    ),
                    acc,
                ]
            ),
        ),
    )
    add("csv_bom", Path(d / "bom.csv"))
    (d / "bom.csv").write_text(
        "\ufefft,x,y\n"
        + body(),
        encoding="utf-8",
    )
    add("csv_quoted", Path(d / "quoted.csv"))
    (d / "quoted.csv").write_text(
        '"t","x","y"\n'
        + body(),
        encoding="utf-8",
    )
    add("csv_ragged", Path(d / "ragged.csv"))
    (d / "ragged.csv").write_text(
        "t,x,y\n"
        + "\n".join(
            f"{a},{b},{c}" if i != 100 else f"{a},{b}"
            for i, (a, b, c) in enumerate(zip(t, acc[:, 0], acc[:, 1], strict=False))
        ),
        encoding="utf-8",
    )
    add("csv_text_cell", Path(d / "text.csv"))
    (d / "text.csv").write_text(
        "t,x,y\n"
        + "\n".join(
            f"{a},{b},{c}" if i != 100 else f"{a},{b},abc"
            for i, (a, b, c) in enumerate(zip(t, acc[:, 0], acc[:, 1], strict=False))
        ),
        encoding="utf-8",
    )
    add("csv_empty_cell", Path(d / "emptycell.csv"))
    (d / "emptycell.csv").write_text(
        "t,x,y\n"
        + "\n".join(
            f"{a},{b},{c}" if i != 100 else f"{a},{b},"
            for i, (a, b, c) in enumerate(zip(t, acc[:, 0], acc[:, 1], strict=False))
        ),
        encoding="utf-8",
    )
    add("csv_header_only", Path(d / "hdr.csv"))
    (d / "hdr.csv").write_text("t,x,y\n", encoding="utf-8")
    add("csv_empty", Path(d / "empty0.csv"))
    (d / "empty0.csv").write_text("", encoding="utf-8")
    add("csv_time_ms", csv("ms.csv", "time,x,y", np.column_stack([t * 1000, acc])))
    add("csv_t_neg_start", csv("tneg.csv", "t,x,y", np.column_stack([t - 1e9, acc])))
    add("csv_t_epoch", csv("tepoch.csv", "t,x,y", np.column_stack([t + 1.8e9, acc]), fmt="%.6f"))
    add("csv_t_epoch_g", csv("tepoch_g.csv", "t,x,y", np.column_stack([t + 1.8e9, acc])))
    return out


def main() -> None:
    d = Path(sys.argv[1])
    d.mkdir(parents=True, exist_ok=True)
    allc = cases(d)
    names = sys.argv[2:] or list(allc)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for name in names:
        argv = [AVARD, *allc[name]]
        try:
            p = subprocess.run(argv, capture_output=True, text=True, timeout=90, env=env)
            tail = (p.stderr.strip().splitlines() or [""])[-1][:200]
            tb = "Traceback" in p.stderr
            print(f"{name:22s} rc={p.returncode} {'TRACEBACK ' if tb else ''}| {tail}")
            if p.returncode == 0:
                lines = [ln for ln in p.stdout.splitlines() if ln.strip()]
                for ln in lines[:2] + [ln for ln in lines if "velocity" in ln or "χ²" in ln][:3]:
                    print("      ", ln[:160])
        except subprocess.TimeoutExpired:
            print(f"{name:22s} HANG (>90 s)")


if __name__ == "__main__":
    main()
