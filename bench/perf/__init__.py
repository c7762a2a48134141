"""Performance of the package: solver speed, node latency and soak, queries, compile cost, recording
overhead, model selection (auto against full), self-contact and identification."""
