"""Terminal summaries and plots (edges; read only results/trajectory data, never the core)."""

from fracas.report.trajectory import plot_trajectory, print_summary, summary_table

__all__ = ["plot_trajectory", "print_summary", "summary_table"]
