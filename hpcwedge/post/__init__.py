"""After a solve: whole-body configurations, figures and VTU files.

- recovery.py: every node's displacement, reactions and stresses of one configuration.
- plot.py, plot3d.py: `hpcwedge plot`; export.py: `hpcwedge export` (VTU).
"""

__all__ = ["recovery", "plot", "plot3d", "export"]
