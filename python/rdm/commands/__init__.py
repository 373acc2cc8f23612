"""Sub-commands of the ``rdm`` command line, one module each."""
