"""The seed example: a twisted cable buckles, loops and writhes
==============================================================

The seed paper's example (Goyal, Perkins & Lee, section 4): a cable in water, twisted at one
end while the other slides, buckles, loops and writhes into contact with itself.

::

    python examples/seed_example.py            # the paper's resolution: 1000 segments, 45 s
    python examples/seed_example.py --quick    # 50 segments to 22 s: a few seconds
    python examples/seed_example.py -o goyal.nc && hockle plot goyal.nc
    python examples/seed_example.py --quick --plot   # with a figure of Tw, Wr, Lk and energies

It loads cases/goyal-writhing.yaml, prints the simulated time every 5 s of it (a callback),
then the run's events: onset of buckling, first contact, each turn of writhe.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from hockle.api import Callback, simulate
from service.sweeps import member_events
from solver import Case

try:
    HERE = Path(__file__).resolve().parent
except NameError:  # the docs' gallery runs the script from examples/ without __file__
    HERE = Path.cwd()
CASE = HERE.parent / "cases" / "goyal-writhing.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="50 segments to 22 s")
    parser.add_argument("-o", "--output", help="write the result dataset (NetCDF) here")
    parser.add_argument("--plot", action="store_true", help="draw a figure (matplotlib)")
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
    if args.plot:
        import matplotlib.pyplot as plt

        fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
        for name, label in (("twist", "Tw"), ("writhe", "Wr"), ("linking_number", "Lk")):
            top.plot(t, ds[name], label=label)
        top.set_ylabel("turns")
        top.legend()
        for name in ("energy_torsion", "energy_bending", "energy_kinetic"):
            bottom.plot(t, ds[name], label=name.removeprefix("energy_"))
        bottom.set_xlabel("t (s)")
        bottom.set_ylabel("energy (J)")
        bottom.legend()
        top.set_title(f"{case.name}: {case.numerics.n_segments} segments")


if __name__ == "__main__":
    main()
