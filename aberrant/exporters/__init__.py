"""Writers of scenes to other formats (glTF)."""
