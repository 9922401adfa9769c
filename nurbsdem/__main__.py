"""python -m nurbsdem: the command line."""
from .cli import main

main()
