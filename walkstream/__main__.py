from walkstream.cli import main
import sys
sys.exit(main())
