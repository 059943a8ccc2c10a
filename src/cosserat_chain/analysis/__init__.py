"""Analysis of results: energies and diagnostics."""
