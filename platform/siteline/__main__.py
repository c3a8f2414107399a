import sys

from siteline.cli import main

sys.exit(main())
