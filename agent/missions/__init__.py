"""Flight-software rooms, one per paper: each package registers its own controller on import."""
