#!/usr/bin/env python3
"""The growth table of docs/performance.md from `solve --report` JSON files.

Usage: python3 docs/growth.py growth_1000.json growth_4000.json ...

One row per report (in the order given, smallest scene first): patches (the input triangles,
or their pieces under --max-edge), elements,
cluster and exact links, links / (n log2 n), (element, link) pairs per sweep, sweeps, the
seconds of each stage, total, peak memory; then the exponents of a least-squares fit of
log(quantity) against log(n) over all rows and over the last three.
"""

import json
import math
import sys


def load(path):
    with open(path) as f:
        r = json.load(f)
    s = r["stats"]
    st = s.get("stage_seconds", {})
    links = s["link_stats"]
    return {
        # Patches: the input triangles, or their pieces under --max-edge.
        "n": r["counts"]["patches"],
        "elements": s["elements"],
        "cluster": links["cluster_links"],
        "exact": links["exact_links"],
        "pairs": s.get("element_link_pairs", 0),
        "sweeps": s["iterations"],
        "tree": st.get("tree", 0.0),
        "links_s": st.get("links", 0.0),
        "model": st.get("model", 0.0),
        "direct": st.get("direct", 0.0),
        "iterate": st.get("iterate", 0.0),
        "total": r["time_seconds"]["total"],
        "peak": r["peak_memory_bytes"],
        "skipped": s.get("direct_light_skipped", False),
        "coarsened": (s.get("memory") or {}).get("coarsened", []),
    }


def slope(rows, key):
    xs = [math.log(r["n"]) for r in rows]
    ys = [math.log(max(r[key], 1e-12)) for r in rows]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    num = sum((x - mx) * (y - my) for x, y in zip(xs, ys))
    den = sum((x - mx) ** 2 for x in xs)
    return num / den if den > 0 else float("nan")


def main(paths):
    rows = [load(p) for p in paths]
    print(
        "| patches | elements | cluster links | exact links | links / (n log₂ n) "
        "| element-link pairs per sweep | sweeps | tree | links | model | direct light "
        "| sweeps (s) | total | peak memory |"
    )
    print("|" + "---|" * 14)
    for r in rows:
        links = r["cluster"] + r["exact"]
        per = links / (r["n"] * math.log2(r["n"]))
        direct = "skipped" if r["skipped"] else f"{r['direct']:.2f} s"
        note = f" ({', '.join(r['coarsened'])})" if r["coarsened"] else ""
        print(
            f"| {r['n']:,} | {r['elements']:,} | {r['cluster']:,} | {r['exact']:,} | {per:.2f} "
            f"| {r['pairs'] / 1e6:.1f}M | {r['sweeps']} | {r['tree']:.2f} s | {r['links_s']:.2f} s "
            f"| {r['model']:.2f} s | {direct} | {r['iterate']:.2f} s | **{r['total']:.2f} s** "
            f"| {r['peak'] / 2**30:.2f} GiB{note} |"
        )
    for r in rows:
        r["links"] = r["cluster"] + r["exact"]
    print()
    keys = ["links", "pairs", "tree", "links_s", "direct", "iterate", "total", "peak"]
    tail = rows[-3:]
    print("| fitted exponent (quantity ∝ n^k) | " + " | ".join(keys) + " |")
    print("|" + "---|" * (len(keys) + 1))
    print("| all rows | " + " | ".join(f"{slope(rows, k):.2f}" for k in keys) + " |")
    if len(rows) > 3:
        print("| last three | " + " | ".join(f"{slope(tail, k):.2f}" for k in keys) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
