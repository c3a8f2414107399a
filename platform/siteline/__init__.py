"""siteline: drone surveys of construction sites turned into change-detection datasets."""

import logging

__version__ = "0.1.0"

# a library logs and leaves showing its lines to the application (the CLI's -v, Prefect's extra loggers)
logging.getLogger(__name__).addHandler(logging.NullHandler())
