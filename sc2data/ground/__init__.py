"""The shared ground: what every stage builds on (folders, records, formats, errors)."""
