"""Tests of the training package (run from the repository root)."""
