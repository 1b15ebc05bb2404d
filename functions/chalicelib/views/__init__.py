"""What pages show: view models computed from domain values so templates only lay them out, and server-rendered
charts, maps and avatars. No boto3, no HTTP."""
