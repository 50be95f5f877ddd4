import sys

from bearcat.cli.main import main

sys.exit(main())
