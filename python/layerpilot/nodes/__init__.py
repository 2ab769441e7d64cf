"""One long-running process per role (map server, depth, decide, link, sim); `layerpilot up` launches them."""
