import sys

from tonguevis.cli import main

sys.exit(main())
