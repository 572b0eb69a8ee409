import sys

from momentid.cli import main

sys.exit(main())
