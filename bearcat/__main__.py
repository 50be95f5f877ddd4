import sys

from bearcat.cli import main

sys.exit(main())
