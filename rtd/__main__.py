"""``python -m rtd fit TRACER.csv [--model tis] [--json] [--out DIR]`` (see rtd.cli)."""
import sys

from rtd.cli import main

sys.exit(main())
