"""``python -m ranad_cli`` runs the ``ranad`` command."""

from .main import main

main()
