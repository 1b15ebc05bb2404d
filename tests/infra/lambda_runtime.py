"""A stand-in for the AWS Lambda Python runtime, enough to drive a packaged function with real events.

The function runs in its own interpreter (`python -I -S`: no site-packages, no PYTHON* variables) that sees only the
unzipped bundle and the packages the Lambda runtime ships (boto3 and its dependencies), with exactly the environment
the caller gives it, as Lambda gives a function its configuration's variables. The handler is loaded from its
`module.attribute` name, once (a warm container), and each event is one JSON line in, one JSON line out.
"""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path
from typing import Any

# What the AWS Lambda Python runtime ships besides the standard library (tests/infra/test_bundle.py checks the
# bundle imports with only these).
LAMBDA_RUNTIME_PACKAGES = ("boto3", "botocore", "s3transfer", "jmespath", "dateutil", "urllib3", "six")

_RUNTIME_LOOP = textwrap.dedent("""
    import importlib, json, os, sys, time
    bundle, runtime, handler_name = sys.argv[1], sys.argv[2], sys.argv[3]
    sys.path[:0] = [bundle, runtime]
    replies = sys.stdout
    sys.stdout = sys.stderr  # what the function prints goes to its log, never into the replies
    module_name, _, attribute = handler_name.rpartition(".")
    handler = getattr(importlib.import_module(module_name), attribute)

    class Context:  # the attributes of the Lambda context object (docs: python-context)
        function_name = os.environ["AWS_LAMBDA_FUNCTION_NAME"]
        function_version = "$LATEST"
        memory_limit_in_mb = int(os.environ["AWS_LAMBDA_FUNCTION_MEMORY_SIZE"])
        invoked_function_arn = os.environ["DREM_TEST_FUNCTION_ARN"]
        log_group_name = os.environ["AWS_LAMBDA_LOG_GROUP_NAME"]
        log_stream_name = "local"
        def __init__(self, request_id, deadline):
            self.aws_request_id, self._deadline = request_id, deadline
        def get_remaining_time_in_millis(self):
            return max(0, int((self._deadline - time.monotonic()) * 1000))

    timeout_s = float(os.environ["DREM_TEST_FUNCTION_TIMEOUT"])
    for line in sys.stdin:
        invocation = json.loads(line)
        context = Context(invocation["request_id"], time.monotonic() + timeout_s)
        replies.write(json.dumps(handler(invocation["event"], context)) + "\\n")
        replies.flush()
""")


def runtime_dir(parent: Path) -> Path:
    """A directory holding only the packages Lambda provides, linked from this venv."""
    runtime = parent / "lambda-runtime"
    runtime.mkdir(exist_ok=True)
    for name in LAMBDA_RUNTIME_PACKAGES:
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin, f"{name} is not installed in the test venv"
        source = Path(spec.origin)
        source = source.parent if source.name == "__init__.py" else source
        (runtime / source.name).symlink_to(source)
    return runtime


class LambdaFunction:
    """One warm container of a function: `invoke(event)` returns what the handler returned."""

    def __init__(self, bundle: Path, runtime: Path, configuration: dict[str, Any], extra_env: dict[str, str],
                 log_file: Path) -> None:
        env = {**configuration.get("Environment", {}).get("Variables", {}), **extra_env,
               "AWS_LAMBDA_FUNCTION_NAME": configuration["FunctionName"],
               "AWS_LAMBDA_FUNCTION_MEMORY_SIZE": str(configuration["MemorySize"]),
               "AWS_LAMBDA_LOG_GROUP_NAME": configuration.get("LoggingConfig", {}).get("LogGroup", ""),
               "DREM_TEST_FUNCTION_ARN": configuration["FunctionArn"],
               "DREM_TEST_FUNCTION_TIMEOUT": str(configuration["Timeout"]),
               "LAMBDA_TASK_ROOT": str(bundle), "PATH": "/usr/bin:/bin"}
        self.log_file = log_file
        self._log = log_file.open("w")
        self._process = subprocess.Popen(
            [sys.executable, "-I", "-S", "-c", _RUNTIME_LOOP, str(bundle), str(runtime), configuration["Handler"]],
            cwd=bundle, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, text=True)

    def invoke(self, event: dict[str, Any]) -> dict[str, Any]:
        assert self._process.stdin is not None and self._process.stdout is not None
        self._process.stdin.write(json.dumps({"event": event, "request_id": str(uuid.uuid4())}) + "\n")
        self._process.stdin.flush()
        reply = self._process.stdout.readline()
        assert reply, f"the function exited ({self._process.poll()}):\n{self.log_tail()}"
        return json.loads(reply)

    def log_tail(self, lines: int = 40) -> str:
        self._log.flush()
        return "\n".join(self.log_file.read_text().splitlines()[-lines:])

    def close(self) -> None:
        if self._process.stdin is not None:
            self._process.stdin.close()
        try:
            self._process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        self._log.close()
