import sys

from walkstream.cli import main

sys.exit(main())
