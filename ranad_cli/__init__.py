"""ranad's command-line interface: click commands that parse, validate, call ranad_core and report."""
