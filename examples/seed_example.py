"""The seed paper's example (Goyal, Perkins & Lee, section 4): a cable in water, twisted at one
end while the other slides, buckles, loops and writhes into contact with itself.

    python examples/seed_example.py            # the paper's resolution: 1000 segments, 45 s
    python examples/seed_example.py --quick    # 50 segments to 22 s: a few seconds
    python examples/seed_example.py -o goyal.nc && hockle plot goyal.nc

It loads cases/goyal-writhing.yaml, prints the simulated time every 5 s of it (a callback),
then the run's events: onset of buckling, first contact, each turn of writhe.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from hockle.api import Callback, simulate
from service.sweeps import member_events
from solver import Case

CASE = Path(__file__).resolve().parents[1] / "cases" / "goyal-writhing.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="50 segments to 22 s")
    parser.add_argument("-o", "--output", help="write the result dataset (NetCDF) here")
    args = parser.parse_args()

    case = Case.from_file(CASE)
    if args.quick:
        # the same case, coarser and shorter: edit the validated model's fields and check again
        doc = case.model_dump(mode="json")
        doc["numerics"].update(n_segments=50, ds=None, t_end=22.0)
        case = Case.model_validate(doc)

    def report(state):
        print(f"t = {state.t:5.1f} s  writhe {state.writhe:6.3f} turns  "
              f"contacts {state.contact_count}")

    ds = simulate(case, callbacks=[Callback(report, interval=5.0)])
    t = ds["time"].values
    for event, index in member_events(ds).items():
        when = "did not happen" if index is None else f"at t = {t[index]:.1f} s"
        print(f"{event.replace('_', ' '):>15}: {when}")
    print(f"{ds.attrs['hockle_status']} in {ds.attrs['wall_time_s']:.1f} s wall time; "
          f"final Tw {float(ds['twist'][-1]):.2f}, Wr {float(ds['writhe'][-1]):.2f}, "
          f"Lk {float(ds['linking_number'][-1]):.2f} turns")
    if args.output:
        from hockle.io import write_netcdf

        print(f"wrote {write_netcdf(ds, args.output)}")


if __name__ == "__main__":
    main()
