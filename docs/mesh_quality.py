#!/usr/bin/env python3
"""Maps mesh-quality variants' results back to the original triangles and tabulates them.

Python 3 standard library only. Used by docs/mesh_quality.sh; also usable on its own:

    mesh_quality.py error ORIGINAL.csv VARIANT.csv VARIANT.map.csv
        prints the variant's difference from the original: the design note's error measure
        (area-weighted relative L1 over the original's non-emissive triangles, mean over the
        RGB channels whose original is not all zero), after mapping the variant's per-triangle
        radiance back to the original triangles through the map. With "-" for the map the
        two CSVs are of the same triangles: the error of a solve against a reference.

    mesh_quality.py common ORIGINAL.csv VARIANT.csv VARIANT.map.csv
        prints the same measure at the resolution the two meshes share: the original and variant
        triangles that overlap (through the map, on the original's side) are joined into groups,
        and each group's area-weighted mean radiance is compared. Where the variant refines the
        original (fan, tjunction, jitter) each group is one original triangle and the two
        measures agree; where it coarsens it (huge-tiny: one triangle for many originals) a
        group holds what both can resolve, and the difference no longer counts the
        resolution the variant gave up.

    mesh_quality.py elements ORIGINAL.obj ORIGINAL.csv VARIANT_ELEMENTS.csv VARIANT.map.csv
        prints the same measure as `error`, with each original triangle's radiance taken from
        the variant's solved elements (`antiradiance solve --elements`) instead of its
        per-triangle CSV: the area-weighted mean of the elements (of the variant triangles
        covering the original, on its side) over the original triangle, each clipped to it in
        their common plane. It measures the
        solver's own resolution inside a variant triangle that covers many originals
        (huge-tiny). ORIGINAL.obj is read for its vertices and faces (polygons fanned from their
        first corner, as the solver fans convex ones); the variant must share its frame (not the
        translations).

    mesh_quality.py table RUNS.tsv
        prints one markdown table of the runs listed in RUNS.tsv (tab-separated, no header:
        scene, variant, status, variant OBJ, report JSON, triangles CSV, map CSV or "-"); the
        first run of each scene named "original" is the reference for its ratios and
        differences.

CSV formats: triangles `index,area,emissive,r,g,b` (`antiradiance solve --triangles`), map
`variant_index,original_index,area,facing` (`antiradiance scene variant`). A variant
triangle's result counts for an original triangle with the weight of the original's area it
covers, on the side the original faces (facing 1; the reversed twins, facing -1, do not count).
"""

import csv
import json
import sys


def read_triangles(path):
    """Rows of a triangles CSV as (area, emissive, (r, g, b)), in index order."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = []
    for i, row in enumerate(rows):
        if int(row["index"]) != i:
            raise ValueError(f"{path}: row {i + 2}: index {row['index']} out of order")
        out.append(
            (
                float(row["area"]),
                row["emissive"].strip() == "1",
                (float(row["r"]), float(row["g"]), float(row["b"])),
            )
        )
    return out


def read_map(path):
    """Rows of a map CSV as (variant, original, area, same_side)."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        if [h.strip() for h in header] != ["variant_index", "original_index", "area", "facing"]:
            raise ValueError(f"{path}: unexpected header {header}")
        return [
            (int(v), int(o), float(a), int(s) == 1)
            for v, o, a, s in (r for r in reader if r)
        ]


def map_back(mapping, originals, variant):
    """Per original triangle, the area-weighted mean of the variant's radiance over the variant
    triangles covering it on its own side (plain mean when their areas sum to 0)."""
    weighted = [[0.0, 0.0, 0.0] for _ in range(originals)]
    plain = [[0.0, 0.0, 0.0] for _ in range(originals)]
    area = [0.0] * originals
    count = [0] * originals
    for v, o, a, same_side in mapping:
        if not same_side:
            continue
        b = variant[v][2]
        for c in range(3):
            weighted[o][c] += a * b[c]
            plain[o][c] += b[c]
        area[o] += a
        count[o] += 1
    out = []
    for o in range(originals):
        if area[o] > 0:
            out.append(tuple(x / area[o] for x in weighted[o]))
        elif count[o] > 0:
            out.append(tuple(x / count[o] for x in plain[o]))
        else:
            out.append((0.0, 0.0, 0.0))
    return out


def relative_error(original, estimate):
    """The design note's error of `estimate` (per original triangle) against `original`."""
    total, channels = 0.0, 0
    for c in range(3):
        num = den = 0.0
        for (a, emissive, b), e in zip(original, estimate):
            if emissive:
                continue
            num += a * abs(e[c] - b[c])
            den += a * b[c]
        if den > 0:
            total += num / den
            channels += 1
    return total / channels if channels else 0.0


def difference(original_csv, variant_csv, map_csv):
    """The variant's difference from the original, mapped back through `map_csv`."""
    original = read_triangles(original_csv)
    variant = read_triangles(variant_csv)
    if map_csv == "-":
        if len(variant) != len(original):
            raise ValueError(f"{variant_csv}: {len(variant)} triangles, {original_csv} has {len(original)}")
        return relative_error(original, [b for _, _, b in variant])
    mapping = read_map(map_csv)
    return relative_error(original, map_back(mapping, len(original), variant))


def common_difference(original_csv, variant_csv, map_csv):
    """The variant's difference from the original on the groups of triangles that overlap
    (connected through the map): per group and channel, the original's area-weighted mean over
    its non-emissive triangles against the variant's over its overlaps with them, weighted by
    the group's original area; summed and divided as in `relative_error`."""
    original = read_triangles(original_csv)
    variant = read_triangles(variant_csv)
    mapping = [m for m in read_map(map_csv) if m[3]]
    parent = list(range(len(original) + len(variant)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for v, o, _, _ in mapping:
        a, b = find(o), find(len(original) + v)
        if a != b:
            parent[a] = b
    # Per group: original area, original sums, overlap area, variant sums.
    groups = {}
    for o, (a, emissive, b) in enumerate(original):
        if emissive:
            continue
        g = groups.setdefault(find(o), [0.0, [0.0] * 3, 0.0, [0.0] * 3])
        g[0] += a
        for c in range(3):
            g[1][c] += a * b[c]
    for v, o, a, _ in mapping:
        if original[o][1]:
            continue
        g = groups[find(o)]
        g[2] += a
        for c in range(3):
            g[3][c] += a * variant[v][2][c]
    total, channels = 0.0, 0
    for c in range(3):
        num = sum(
            abs((g[3][c] / g[2] if g[2] > 0 else 0.0) * g[0] - g[1][c]) for g in groups.values()
        )
        den = sum(g[1][c] for g in groups.values())
        if den > 0:
            total += num / den
            channels += 1
    return total / channels if channels else 0.0


def read_obj_triangles(path):
    """The triangles of an OBJ file as corner triples, faces fanned from their first corner."""
    vertices, triangles = [], []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                vertices.append(tuple(float(x) for x in parts[1:4]))
            elif parts[0] == "f":
                ids = []
                for token in parts[1:]:
                    i = int(token.split("/")[0])
                    ids.append(i - 1 if i > 0 else len(vertices) + i)
                for k in range(1, len(ids) - 1):
                    triangles.append((vertices[ids[0]], vertices[ids[k]], vertices[ids[k + 1]]))
    return triangles


def read_elements(path):
    """Rows of an elements CSV grouped by input triangle: {triangle: [(corners, (r, g, b))]}."""
    out = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            corners = tuple(
                tuple(float(row[f"{axis}{k}"]) for axis in "xyz") for k in range(3)
            )
            rgb = (float(row["r"]), float(row["g"]), float(row["b"]))
            out.setdefault(int(row["triangle"]), []).append((corners, rgb))
    return out


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def clipped_area(subject, clip, axes):
    """The area of triangle `subject` inside triangle `clip` (both in one plane), in the 2-D
    coordinates `axes` of that plane (Sutherland and Hodgman), scaled back to 3-D by the
    caller."""
    def to2(p):
        return (p[axes[0]], p[axes[1]])

    polygon = [to2(p) for p in subject]
    c = [to2(p) for p in clip]
    # Orient the clip triangle counter-clockwise.
    if (c[1][0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[1][1] - c[0][1]) * (c[2][0] - c[0][0]) < 0:
        c = [c[0], c[2], c[1]]
    for k in range(3):
        a, b = c[k], c[(k + 1) % 3]
        side = lambda p: (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
        out = []
        for m in range(len(polygon)):
            p, q = polygon[m], polygon[(m + 1) % len(polygon)]
            sp, sq = side(p), side(q)
            if sp >= 0:
                out.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        polygon = out
        if not polygon:
            return 0.0
    area = 0.0
    for m in range(len(polygon)):
        p, q = polygon[m], polygon[(m + 1) % len(polygon)]
        area += p[0] * q[1] - q[0] * p[1]
    return abs(area) / 2


def element_difference(original_obj, original_csv, elements_csv, map_csv):
    """The variant's difference from the original, each original triangle's radiance the
    area-weighted mean of the variant's elements over it (see the module's `elements`)."""
    original = read_triangles(original_csv)
    triangles = read_obj_triangles(original_obj)
    if len(triangles) != len(original):
        raise ValueError(f"{original_obj}: {len(triangles)} triangles, {original_csv} has {len(original)}")
    elements = read_elements(elements_csv)
    covering = {}
    for v, o, _, same_side in read_map(map_csv):
        if same_side:
            covering.setdefault(o, []).append(v)
    estimate = []
    for o, corners in enumerate(triangles):
        a, b, c = corners
        n = (
            (b[1] - a[1]) * (c[2] - a[2]) - (b[2] - a[2]) * (c[1] - a[1]),
            (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2]),
            (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]),
        )
        drop = max(range(3), key=lambda k: abs(n[k]))
        axes = [k for k in range(3) if k != drop]
        # Projected areas back to the plane's: divide by |n_drop| / |n|.
        stretch = dot(n, n) ** 0.5 / abs(n[drop]) if n[drop] != 0 else 0.0
        total, weighted = 0.0, [0.0, 0.0, 0.0]
        for v in covering.get(o, []):
            for element, rgb in elements.get(v, []):
                area = clipped_area(element, corners, axes) * stretch
                total += area
                for k in range(3):
                    weighted[k] += area * rgb[k]
        estimate.append(tuple(x / total for x in weighted) if total > 0 else (0.0, 0.0, 0.0))
    return relative_error(original, estimate)


def count_faces(obj):
    """Triangles of an OBJ file after fan triangulation."""
    n = 0
    try:
        with open(obj) as f:
            for line in f:
                words = line.split("#")[0].split()
                if words and words[0] == "f":
                    n += len(words) - 3
    except OSError:
        return None
    return n


def fmt(x, digits=3):
    """A number with `digits` significant digits, plain for moderate magnitudes."""
    if x is None:
        return "-"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e6:
        return f"{x:.{digits}g}"
    return f"{x:.{digits - 1}e}"


def table(runs_tsv):
    """One markdown table of the runs in `runs_tsv`."""
    rows = []
    with open(runs_tsv) as f:
        for line in f:
            if line.strip():
                rows.append(line.rstrip("\n").split("\t"))
    print(
        "| scene | variant | input triangles | time (s) | links | links / input triangle "
        "| time ratio | links ratio | peak memory (MB) | difference from original "
        "| at the common resolution |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    base = {}
    for scene, variant, status, obj, report, triangles, mapping in rows:
        n = count_faces(obj)
        if status != "ok":
            print(f"| {scene} | {variant} | {n if n is not None else '-'} | {status} | | | | | | | |")
            continue
        with open(report) as f:
            r = json.load(f)
        n = r["counts"]["input_triangles"]
        t = r["time_seconds"]["total"]
        links = r["stats"]["links"]
        peak = r.get("peak_memory_bytes")
        if variant == "original" and scene not in base:
            base[scene] = (t, links, triangles)
        ref = base.get(scene)
        if ref is None:
            ratios, diff, common = ("-", "-"), "-", "-"
        else:
            ratios = (fmt(t / ref[0]) if ref[0] > 0 else "-", fmt(links / ref[1]) if ref[1] else "-")
            if variant == "original":
                diff = common = "0"
            elif mapping == "-":
                diff = common = "-"
            else:
                try:
                    diff = f"{100 * difference(ref[2], triangles, mapping):.3f}%"
                    common = f"{100 * common_difference(ref[2], triangles, mapping):.3f}%"
                except (OSError, ValueError, IndexError, KeyError) as e:
                    diff = common = f"failed: {e}"
        print(
            f"| {scene} | {variant} | {n} | {fmt(t)} | {links} | {fmt(links / n)} | "
            f"{ratios[0]} | {ratios[1]} | {fmt(peak / 1e6) if peak else '-'} | {diff} | {common} |"
        )


def main(argv):
    if len(argv) == 5 and argv[1] == "error":
        print(f"{difference(argv[2], argv[3], argv[4]):.6g}")
    elif len(argv) == 5 and argv[1] == "common" and argv[4] != "-":
        print(f"{common_difference(argv[2], argv[3], argv[4]):.6g}")
    elif len(argv) == 6 and argv[1] == "elements":
        print(f"{element_difference(argv[2], argv[3], argv[4], argv[5]):.6g}")
    elif len(argv) == 3 and argv[1] == "table":
        table(argv[2])
    else:
        sys.stderr.write(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
