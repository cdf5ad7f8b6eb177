"""The project's own fuzzer (issue 13 item 9): kbfuzz mutates kb files; corpus/ holds known bad cells."""
