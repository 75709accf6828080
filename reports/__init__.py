"""Reports built from run folders (CSV/JSON only: no re-simulation)."""
