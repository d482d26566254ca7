"""Standard elementary behaviors of the Ranger and its Scouts (see each component's manifest)."""
