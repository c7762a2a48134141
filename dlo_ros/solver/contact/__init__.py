"""Contact: obstacle slots, self-contact and the linking number of a clamped string."""
