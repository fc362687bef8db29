import sys

from pecs.cli import main

sys.exit(main())
