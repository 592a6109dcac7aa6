"""A plectoneme built in Python
==============================

A rod in water twisted continuously at one end while the other end slides
along the axis, then is held (at 6.5 s, as the rod starts to bend); past the buckling twist it
loops, the loop wraps onto itself and the writhe climbs turn after turn, the strands held apart
by self-contact.

::

    python examples/plectoneme.py              # 200 segments, 30 s
    python examples/plectoneme.py --quick      # 40 segments, 10 s: a few seconds
    python examples/plectoneme.py --quick --plot   # with the final shape and the writhe

The case is built in Python with hockle.api's end helpers and the case spec's own fields; a
Recorder keeps the shape every second and a callback stops the run at 8 turns of writhe.
"""
from __future__ import annotations

import argparse

import numpy as np

from hockle.api import Callback, Recorder, make_case, simulate, sliding, twisted


def build(quick: bool):
    """The case: the seed's cable (1 m, 2 cm, E 12.5 MPa) in water, the start end turned at
    3 rad/s after a 1-s ramp, the far end held sideways, sliding without load until 6.5 s and
    held from then on (holding it from t = 0 would leave the straight rod's tension
    undetermined: case-spec, ill_posed)."""
    return make_case(
        "plectoneme",
        start=twisted(-3.0, ramp_time=1.0),
        end=sliding(tension=0.0, held_after=6.5),
        n_segments=40 if quick else 200, dt=0.1, t_end=10.0 if quick else 30.0,
        fluid={"density": 1000.0, "drag_coefficient_normal": 1.2},
        # a minute sideways push for 2 s: the imperfection that picks the buckling's plane
        distributed_forces=[{"value": [1e-5, 0.0, 0.0], "start": 0.0, "end": 2.0}],
        contact={"aperture": 90.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0, "k3": 1e-6,
                 "k4": 1.0},
        output={"fields": ["position", "energies", "topology", "contact"]},
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="40 segments, 10 s")
    parser.add_argument("-o", "--output", help="write the result dataset (NetCDF) here")
    parser.add_argument("--plot", action="store_true", help="draw a figure (matplotlib)")
    args = parser.parse_args()

    shapes = Recorder(["position", "writhe", "contact_count"], interval=1.0)
    enough = Callback.when(lambda st: abs(st.writhe) > 8.0, reason="8 turns of writhe",
                           every=5)
    ds = simulate(build(args.quick), callbacks=[shapes, enough])

    rec = shapes.arrays()
    for t, wr, n, pos in zip(rec["time"], rec["writhe"], rec["contact_count"], rec["position"]):
        span = np.linalg.norm(pos[-1] - pos[0])
        print(f"t = {t:4.1f} s  Wr {wr:6.2f}  contacts {int(n):3d}  end-to-end {span:.3f} m")
    print(f"{ds.attrs['hockle_status']} at t = {float(ds['time'][-1]):.1f} s "
          f"({ds.attrs.get('hockle_stop_reason', 'to t_end')}); "
          f"{ds.attrs['wall_time_s']:.1f} s wall time")
    if args.output:
        from hockle.io import write_netcdf

        print(f"wrote {write_netcdf(ds, args.output)}")
    if args.plot:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(9, 4.5))
        ax = fig.add_subplot(1, 2, 1, projection="3d")
        pos = np.asarray(ds["position"].isel(time=-1))
        ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], lw=3)
        ax.set_title(f"t = {float(ds['time'][-1]):.1f} s")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        right = fig.add_subplot(1, 2, 2)
        right.plot(ds["time"], ds["writhe"], label="Wr")
        right.plot(ds["time"], ds["linking_number"], label="Lk")
        right.set_xlabel("t (s)")
        right.set_ylabel("turns")
        right.legend()


if __name__ == "__main__":
    main()
