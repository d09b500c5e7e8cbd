"""Importers: scenes from other engines' files, converted to aberrant scene files."""
