"""imaging: reserved for a later issue (see DESIGN.md); empty for now."""
