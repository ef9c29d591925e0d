# SPDX-License-Identifier: MIT
"""The real-data corpus test's result line (test_real_corpus.sh): printed, appended to the results TSV (with the
failures, if any), and the exit status."""
import sys


def finish(cid, line, fails, results):
    print(line)
    if results:
        with open(results, "a") as f:
            f.write(line + ("\tFAIL: " + "; ".join(fails) if fails else "") + "\n")
    if fails:
        print("FAIL %s: %s" % (cid, "; ".join(fails)))
        sys.exit(1)
