"""The base every layer stands on: input errors, atomic file I/O, project-wide defaults, the HTML page shell."""
