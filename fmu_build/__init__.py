"""Builds dist/PRSM<n>.fmu with pythonfmu, completes its modelDescription.xml and validates it (to come)."""
