"""`python -m mapqual` runs the command line."""

from mapqual.cli import main

main()
