"""Batch experiments: expansion into keyed runs, a local process pool, resumable state, tables,
plots and report.html (`mapqual batch` is the shell over this package)."""
