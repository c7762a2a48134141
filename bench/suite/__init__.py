"""The speed-vs-accuracy suite (run_all), the stability map and the paper's examples, with their references."""
