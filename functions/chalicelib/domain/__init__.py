"""Pure, typed domain logic: pydantic models and services. No boto3, no HTTP."""
