"""The command-line shells: the only place that prints, colours (rich) or exits."""
