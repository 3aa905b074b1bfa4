"""The example drive descriptions (default.toml: what no --drive means) and their data."""
