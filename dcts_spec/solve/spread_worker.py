"""A worker process of `sensitivity.spreads`: reads a pickled list of (AnswerData, samples, enough)
from stdin, writes the pickled list of their spreads to stdout."""

import os
import pickle
import sys

if __name__ == "__main__":
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # (whatever else writes to stdout, an import or a C library, goes to stderr)
    jobs = pickle.load(sys.stdin.buffer)
    pickle.dump([answer.spread(samples, enough) for answer, samples, enough in jobs], out)
    out.close()
