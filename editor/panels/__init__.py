"""The editor's panels: each draws one imgui window, menu or dialog, and edits only through the model."""
