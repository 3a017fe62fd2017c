"""Seeded random branched circuits of 20 units for the layout tests (not a test module).

A circuit has one or two feeds, one to three products and mills, mixers, sumps,
hydrocyclones, screens and splitters between them: each unit is fed from an earlier one
(the one before it, or any earlier one), a classifier or splitter sends its second stream
forward, to a product or back to an earlier unit (a recycle), and up to four more
recycles join later units to earlier ones. Stream names are drawn from plant words, some
of them long; each stream gets a wet label with numbers of plausible size.
"""
import random

from millflow.report.flowsheet import stream_label

WORDS = ["feed", "mill", "discharge", "cyclone", "overflow", "underflow", "screen", "oversize", "undersize",
         "regrind", "primary", "secondary", "sump", "pump", "chute", "fines", "coarse", "return", "to",
         "flotation", "cluster", "tertiary", "recycle", "product"]
MIDDLE = ["mill", "mixer", "sump", "hydrocyclone", "screen", "splitter"]
TWO_OUT = {"hydrocyclone", "screen", "splitter"}


def random_circuit(seed: int, n_units: int = 20):
    """(units, streams, labels) of a random circuit: unit -> type, stream -> (source,
    target), stream -> label lines (as report.html draws them)."""
    r = random.Random(seed)
    n_feeds, n_products = r.choice([1, 1, 2]), r.choice([1, 2, 3])
    feeds = [f"feed_{k}" for k in range(n_feeds)]
    middle = [f"{t}_{k}" for k, t in enumerate(r.choice(MIDDLE) for _ in range(n_units - n_feeds - n_products))]
    products = [f"product_{k}" for k in range(n_products)]
    units = {**{u: "feed" for u in feeds}, **{u: u.rsplit("_", 1)[0] for u in middle},
             **{u: "product" for u in products}}
    streams, used = {}, set()

    def name():
        k = r.choice([1, 2, 2, 3, 3, 4, 6])
        base = "_".join(r.choice(WORDS) for _ in range(k))
        while base in used:
            base += f"_{r.randrange(10)}"
        used.add(base)
        return base

    order = feeds + middle
    for k, u in enumerate(middle):
        earlier = order[:n_feeds + k]
        src = earlier[-1] if r.random() < 0.6 else r.choice(earlier)
        streams[name()] = (src, u)
    for f in feeds[1:]:
        if not any(s == f for s, _ in streams.values()):
            streams[name()] = (f, r.choice(middle[:3]))
    for k, u in enumerate(middle):
        if units[u] in TWO_OUT:
            p = r.random()
            tgt = (r.choice(products) if p < 0.4 else r.choice(middle[:k + 1]) if p < 0.7
                   else r.choice(middle[k + 1:] or products))
            streams[name()] = (u, tgt)
    for u in middle:
        if not any(s == u for s, _ in streams.values()):
            streams[name()] = (u, r.choice(products))
    for p in products:
        if not any(t == p for _, t in streams.values()):
            streams[name()] = (r.choice(middle), p)
    for _ in range(r.randrange(5)):
        a = r.randrange(3, len(middle))
        streams[name()] = (middle[a], middle[r.randrange(0, a)])
    labels = {}
    for n in streams:
        solids = 10 ** r.uniform(0, 3.2)
        water = 10 ** r.uniform(0, 3.2)
        s = {"solids_tph": solids, "water_tph": water, "solids_content_pct": 100 * solids / (solids + water),
             "p80_um": 10 ** r.uniform(1, 4)}
        labels[n] = stream_label(n, s)
    return units, streams, labels
