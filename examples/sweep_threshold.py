"""A parameter sweep: buckling against end tension
=================================================

When does a twisted rod buckle, against the tension on its end?

::

    python examples/sweep_threshold.py                 # 8 tensions, 100 segments, here
    python examples/sweep_threshold.py --quick         # 3 tensions, 30 segments: seconds
    python examples/sweep_threshold.py --url http://127.0.0.1:8000   # on a hockle service
    python examples/sweep_threshold.py -o sweep.nc && hockle plot sweep.nc
    python examples/sweep_threshold.py --quick --plot  # with the threshold curve

The base case is a rod turned at one end at a steady rate while its other end slides under a
tension; the sweep varies the tension (the dotted path boundary.end.translation.2.force).
Every member's onset of buckling (the centreline a diameter off its chord) and the linking
number it had taken then come back in the combined dataset (event_time,
event_linking_number): the more tension, the more twist the rod stores before it buckles.
"""
from __future__ import annotations

import argparse

import numpy as np

from hockle.api import make_case, sliding, sweep, twisted

TENSION = "boundary.end.translation.2.force"


def build(quick: bool):
    return make_case(
        "twist against tension",
        start=twisted(-2.0), end=sliding(0.0),
        n_segments=30 if quick else 100, dt=0.1, t_end=12.0 if quick else 20.0,
        fluid={"density": 1000.0},
        distributed_forces=[{"value": [1e-5, 0.0, 0.0], "start": 0.0, "end": 2.0}],
        output={"fields": ["position", "energies", "topology"]},
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 tensions, 30 segments")
    parser.add_argument("--url", help="run the members on this hockle service")
    parser.add_argument("-o", "--output", help="write the combined dataset (NetCDF) here")
    parser.add_argument("--plot", action="store_true", help="draw a figure (matplotlib)")
    args = parser.parse_args()

    tensions = [0.0, 0.5, 1.0] if args.quick else list(np.round(np.linspace(0.0, 1.4, 8), 3))
    base = build(args.quick)
    if args.url:
        from service.client import HockleClient

        with HockleClient(args.url) as client:
            status = client.sweep(base, {TENSION: tensions}, wait=True,
                                  on_progress=lambda s: print(f"{s.state} {s.progress:.0f}%"))
            ds = client.sweep_dataset(status.id)
    else:
        ds = sweep(base, {TENSION: tensions},
                   on_member=lambda done, total, i, state: print(f"member {i}: {state} "
                                                                 f"({done}/{total})"))
    onset = ds["event_time"].sel(event="buckling_onset")
    lk = ds["event_linking_number"].sel(event="buckling_onset")
    print(f"{'tension (N)':>12} {'onset (s)':>10} {'|Lk| at onset (turns)':>22}  status")
    for k, tension in enumerate(ds[TENSION].values):
        print(f"{tension:12.3f} {float(onset[k]):10.2f} {abs(float(lk[k])):22.3f}  "
              f"{ds['member_status'].values[k]}")
    if args.output:
        from hockle.io import write_netcdf

        print(f"wrote {write_netcdf(ds, args.output)}")
    if args.plot:
        import matplotlib.pyplot as plt

        fig, (left, right) = plt.subplots(1, 2, figsize=(9, 4))
        left.plot(ds[TENSION], onset, "o-")
        left.set_xlabel("end tension (N)")
        left.set_ylabel("buckling onset (s)")
        right.plot(ds[TENSION], np.abs(lk), "o-")
        right.set_xlabel("end tension (N)")
        right.set_ylabel("|Lk| at onset (turns)")
        fig.tight_layout()


if __name__ == "__main__":
    main()
