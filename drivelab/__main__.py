"""``python -m drivelab``: the ``drivelab`` command."""

from drivelab.cli import main

main()
