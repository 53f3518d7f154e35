"""Visual QA: HTML reports with plots, and Rerun recordings."""
