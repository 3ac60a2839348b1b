#!/usr/bin/env python3
"""The figures of examples/two-group/run.sh (stdlib only).

usage: dice.py OUT FACTOR T_START T_MADE T_FITTED T_TESTED

Truth: the atoms whose planted spoke factor (OUT/cases/p1/thickening.csv, the same for every
patient) exceeds 1 + (FACTOR - 1) / 2, the bump's half-height region. Found: the atoms of
OUT/stats/stats.vtk (one point per atom of the template, in the atoms' order) with p_fwer
(max-t) <= 0.05, and those with p_tfce <= 0.05. The null study (OUT/stats_null) must have no atom
with p_fwer <= 0.05. Exit 1 when the TFCE Dice (the required figure; max-t's is reported
beside it) is below 0.7 or the null study finds an atom.
"""
import csv
import json
import struct
import sys

ALPHA = 0.05


SIZES = {"double": 8, "float": 4, "int": 4, "unsigned_int": 4, "vtktypeint64": 8, "long": 8,
         "unsigned_long": 8, "vtktypeuint64": 8, "short": 2, "unsigned_short": 2, "char": 1,
         "unsigned_char": 1, "bit": 1}
FORMATS = {"double": "d", "float": "f", "int": "i", "unsigned_int": "I", "vtktypeint64": "q",
           "long": "q", "unsigned_long": "Q", "vtktypeuint64": "Q", "short": "h",
           "unsigned_short": "H", "char": "b", "unsigned_char": "B"}


def point_arrays(path):
    """The POINT_DATA arrays of a legacy VTK polydata file (ASCII or BINARY, as medial writes
    them): name -> list of floats."""
    data = open(path, "rb").read()
    pos = 0

    def line():
        nonlocal pos
        while data[pos : pos + 1] in (b"\n", b"\r", b" "):
            pos += 1
        if pos >= len(data):
            return []
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        text = data[pos:end].decode("latin-1").split()
        pos = end + 1
        return text

    def values(count, kind):
        nonlocal pos
        if binary:
            size = SIZES[kind]
            out = struct.unpack(f">{count}{FORMATS[kind]}", data[pos : pos + count * size])
            pos += count * size
            return [float(v) for v in out]
        out = []
        while len(out) < count:
            out += [float(v) for v in line()]
        return out

    line(), line()
    binary = line()[0] == "BINARY"
    arrays, in_points, n = {}, False, 0
    while pos < len(data):
        words = line()
        if not words:
            continue
        key = words[0]
        if key == "DATASET":
            continue
        if key == "POINTS":
            values(3 * int(words[1]), words[2])
        elif key in ("POLYGONS", "LINES", "VERTICES", "TRIANGLE_STRIPS"):
            # new layout: OFFSETS and CONNECTIVITY blocks follow; old: size ints
            save = pos
            nxt = line()
            if nxt and nxt[0] == "OFFSETS":
                values(int(words[1]), nxt[1])
                conn = line()
                values(int(words[2]), conn[1])
            else:
                pos = save
                values(int(words[2]), "int")
        elif key == "POINT_DATA":
            in_points, n = True, int(words[1])
        elif key == "CELL_DATA":
            if in_points:
                break
            n = int(words[1])
        elif key in ("SCALARS", "NORMALS", "VECTORS"):
            comps = 3 if key != "SCALARS" else int(words[3]) if len(words) > 3 else 1
            if key == "SCALARS":
                line()  # LOOKUP_TABLE
            got = values(n * comps, words[2])
            if in_points:
                arrays[words[1]] = got
        elif key == "FIELD":
            for _ in range(int(words[2])):
                name, comps, tuples, kind = line()
                got = values(int(comps) * int(tuples), kind)
                if in_points:
                    arrays[name] = got
        else:
            raise SystemExit(f"{path}: unexpected '{key}'")
    return arrays


def dice(a, b):
    return 2 * len(a & b) / (len(a) + len(b)) if a or b else 1.0


def main():
    out, factor = sys.argv[1], float(sys.argv[2])
    t_start, t_made, t_fitted, t_tested = (float(v) for v in sys.argv[3:7])
    with open(f"{out}/cases/p1/thickening.csv") as f:
        factors = {int(r["atom"]): float(r["factor"]) for r in csv.DictReader(f)}
    half = 1 + (factor - 1) / 2
    truth = {a for a, f in factors.items() if f > half}
    bump = {a for a, f in factors.items() if f > 1}
    study = point_arrays(f"{out}/stats/stats.vtk")
    null = point_arrays(f"{out}/stats_null/stats.vtk")
    atoms = len(study["p_fwer"])
    found_fwer = {a for a, p in enumerate(study["p_fwer"]) if p <= ALPHA}
    found_tfce = {a for a, p in enumerate(study["p_tfce"]) if p <= ALPHA}
    null_fwer = {a for a, p in enumerate(null["p_fwer"]) if p <= ALPHA}
    null_tfce = {a for a, p in enumerate(null["p_tfce"]) if p <= ALPHA}
    with open(f"{out}/batch/cohort.csv") as f:
        rows = list(csv.DictReader(f))
    usable = sum(r["status"] in ("converged", "budget") for r in rows)
    summary = json.load(open(f"{out}/stats/summary.json"))
    left_out = summary.get("left_out", [])
    tested = summary.get("subjects")
    d_fwer, d_tfce = dice(found_fwer, truth), dice(found_tfce, truth)
    lines = [
        f"subjects fitted: {len(rows)} ({usable} usable: converged or budget); "
        f"tested {tested}, left out {len(left_out)}",
        f"atoms: {atoms}; planted bump (factor > 1): {len(bump)} atoms; "
        f"truth (factor > {half:g}): {len(truth)} atoms {sorted(truth)}",
        f"study, max-t p_fwer <= {ALPHA}: {len(found_fwer)} atoms {sorted(found_fwer)}; "
        f"in the truth {len(found_fwer & truth)}, outside it {len(found_fwer - truth)} "
        f"(of which outside the bump {len(found_fwer - bump)}); Dice {d_fwer:.3f}",
        f"study, TFCE p_tfce <= {ALPHA}: {len(found_tfce)} atoms; in the truth "
        f"{len(found_tfce & truth)}, outside it {len(found_tfce - truth)} "
        f"(outside the bump {len(found_tfce - bump)}); Dice {d_tfce:.3f}",
        f"study: largest t {max(study['t']):.2f}, smallest p_fwer {min(study['p_fwer']):.4g}",
        f"null study: atoms with p_fwer <= {ALPHA}: {len(null_fwer)}, with p_tfce <= {ALPHA}: "
        f"{len(null_tfce)}; largest t {max(null['t']):.2f}, smallest p_fwer "
        f"{min(null['p_fwer']):.4g}, smallest p_tfce {min(null['p_tfce']):.4g}",
        f"seconds: {t_tested - t_start:.0f} in all ({t_made - t_start:.0f} making the subjects, "
        f"{t_fitted - t_made:.0f} fitting, {t_tested - t_fitted:.1f} testing)",
    ]
    ok = d_tfce >= 0.7 and not null_fwer
    lines.append("PASS: Dice (TFCE) >= 0.7 and nothing in the null study" if ok else
                 "FAIL: Dice (TFCE) below 0.7 or something found in the null study")
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
