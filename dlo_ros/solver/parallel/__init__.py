"""Many independent solves at once: batches over a pool of worker processes."""
