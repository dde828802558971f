"""python -m layerskin_exp.log inspect FILE | recover IN OUT | layout platform|gripper|FILE |
export lerobot SESSIONS OUT [--fps N] | view SESSION... [--web] [--save OUT]"""

import sys

from layerskin_exp.log.cli import main

sys.exit(main())
