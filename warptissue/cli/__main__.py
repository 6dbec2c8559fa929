import sys

from warptissue.cli import main

sys.exit(main())
