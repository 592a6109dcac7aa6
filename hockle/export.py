"""The ParaView export of ``hockle export`` (:mod:`service.export`, where the service's
dashboard reaches it too), under the name the Python API documents."""
from __future__ import annotations

from service.export import ExportError, export_vtk, read_pvd

__all__ = ["export_vtk", "read_pvd", "ExportError"]
