"""Results in ParaView: the run as a VTK time series
===================================================

``hockle export`` (and ``hockle.export.export_vtk`` behind it) writes a result as a ParaView
data collection: one VTK file per output time, the centreline as line cells with every
per-node field as point data, its frame in its name (``kappa_body``, ``v_global``, ...;
``radius``, ``s``). ParaView opens the ``.pvd`` as a time series; a Tube filter with its
radius varied by the ``radius`` array draws the cable.

::

    python examples/paraview_export.py --quick --plot      # a small plectoneme, seconds
    python examples/paraview_export.py --result goyal.nc --time 32.7 --plot-file frame.png

The frame drawn here is read back from the exported file with meshio and rendered with
matplotlib (no ParaView or VTK needed): the centreline coloured by its bending curvature
the norm of (kappa_body 1, kappa_body 2), in rad/m.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="run a small plectoneme (examples/plectoneme.py) to export")
    parser.add_argument("--result", help="export this result file instead of running one")
    parser.add_argument("--time", type=float, help="the frame to draw, s (default: the last)")
    parser.add_argument("-o", "--output", help="the .pvd to write (default: a temporary "
                        "folder)")
    parser.add_argument("--plot", action="store_true", help="draw the frame (matplotlib)")
    parser.add_argument("--plot-file", help="save the frame as this PNG")
    args = parser.parse_args()

    import meshio

    from hockle.export import export_vtk, read_pvd
    from hockle.io import open_result

    if args.result:
        ds = open_result(args.result)
    else:
        from hockle.api import make_case, simulate, sliding, twisted

        case = make_case(
            "plectoneme", start=twisted(-3.0, ramp_time=1.0),
            end=sliding(tension=0.0, held_after=6.5),
            n_segments=40 if args.quick else 200, dt=0.1, t_end=10.0 if args.quick else 30.0,
            fluid={"density": 1000.0, "drag_coefficient_normal": 1.2},
            distributed_forces=[{"value": [1e-5, 0.0, 0.0], "start": 0.0, "end": 2.0}],
            contact={"aperture": 90.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0, "k3": 1e-6,
                     "k4": 1.0},
            output={"fields": ["position", "kappa", "v", "energies", "topology", "contact"]},
        )
        ds = simulate(case)
    folder = None if args.output else tempfile.TemporaryDirectory()
    pvd = Path(args.output) if args.output else Path(folder.name) / "run.pvd"
    files = export_vtk(ds, pvd, stride=max(1, ds.sizes["time"] // 50))
    frames = read_pvd(pvd)
    print(f"wrote {pvd}: {len(files) - 1} frames, t = {frames[0][0]:g} … {frames[-1][0]:g} s")

    t_want = frames[-1][0] if args.time is None else args.time
    t, path = min(frames, key=lambda f: abs(f[0] - t_want))
    mesh = meshio.read(path)
    print(f"frame at t = {t:g} s: {len(mesh.points)} points, point data "
          f"{', '.join(sorted(mesh.point_data))}")
    if not (args.plot or args.plot_file):
        return
    import matplotlib

    if args.plot_file and not args.plot:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    p = mesh.points
    bend = np.hypot(mesh.point_data["kappa_body"][:, 0], mesh.point_data["kappa_body"][:, 1])
    segments = np.stack([p[:-1], p[1:]], axis=1)
    fig = plt.figure(figsize=(6.5, 6))
    ax = fig.add_subplot(projection="3d")
    lines = Line3DCollection(segments, cmap="viridis", linewidths=4)
    lines.set_array(0.5 * (bend[:-1] + bend[1:]))
    ax.add_collection(lines)
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo)) + 1e-3
    ax.set(xlim=(centre[0] - half, centre[0] + half), ylim=(centre[1] - half, centre[1] + half),
           zlim=(centre[2] - half, centre[2] + half), xlabel="x (m)", ylabel="y (m)",
           zlabel="z (m)")
    fig.colorbar(lines, ax=ax, shrink=0.6, label="bending curvature (rad/m)")
    ax.set_title(f"{path.name} (t = {t:g} s), read back with meshio")
    if args.plot_file:
        fig.savefig(args.plot_file, dpi=110, bbox_inches="tight")
        print(f"saved {args.plot_file}")
    if folder is not None and not args.plot:
        folder.cleanup()


if __name__ == "__main__":
    main()
