"""CLI command groups that are not tied to one model."""
