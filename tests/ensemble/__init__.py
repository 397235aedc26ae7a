"""Ensemble tests: a package, so that their clusters (package-scoped fixtures) close when the folder is done."""
