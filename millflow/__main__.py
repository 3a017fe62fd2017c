import sys

from millflow.cli import main

sys.exit(main())
