"""REST API (FastAPI): one router per resource, pydantic models for every body."""
