import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

# One block per chunk in the stores the tests create (``pipeline._store.chunk_bytes``): a small
# scene then has several chunks to kill, resume and count, as a paper-sized scene has; set in
# the environment so that the drivers the tests start as subprocesses inherit it.  Tests of the
# storage chunks themselves set their own value.
os.environ["TWOLINK_PIPELINE_CHUNK_BYTES"] = "1"
