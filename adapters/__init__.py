"""Placeholder: filled by its own issue (see docs/ARCHITECTURE.md)."""
