"""hpcwedge: wedged configurations of elastic bodies in frictional contact (Fujita & Kanno 2010)."""
__version__ = "0.1.0"
