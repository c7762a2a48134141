"""Building the NLP and its derivatives: layout, rows, assembled KKT functions, compiled calls."""
