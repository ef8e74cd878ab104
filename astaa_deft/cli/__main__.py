"""`python -m astaa_deft.cli ...`: the `astaa-deft` command, for a child process that must use this interpreter."""

import sys

from astaa_deft.cli import main

if __name__ == "__main__":  # a package walk imports this module too
    sys.exit(main())
