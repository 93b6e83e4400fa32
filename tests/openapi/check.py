#!/usr/bin/env python3
"""The OpenAPI document is one a person can use, checked against a live server:

- every operation has a summary and a description;
- every request body has an example, which validates against its schema and which the server
  accepts (2xx) as sent; every query and header parameter has an example;
- every success response has an example for each of its content types (a server's real answer,
  `tools/openapi_examples.py`); a JSON one validates against the response's schema, a text one is
  text, an SVG one is well-formed XML;
- every property of every schema has a description;
- times are `date-time`, ids `uuid`; 201/202 document `Location`, 429 and 503 `Retry-After`, and
  the immutable representations `ETag`;
- every content type the server answers with is documented: CSV, SVG, event streams, text.

Usage: check.py BASE_URL (a server with its default limits and no API keys)."""

import json
import sys
import urllib.error
import urllib.request
import xml.etree.ElementTree as ElementTree

import jsonschema

base = sys.argv[1].rstrip("/")
failures = []


def fail(message):
    failures.append(message)


def call(method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(base + path, data=data, method=method)
    if data is not None:
        request.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.status, response.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.read().decode()


with urllib.request.urlopen(base + "/openapi.json") as response:
    document = json.load(response)
schemas = document["components"]["schemas"]


def validate(instance, schema):
    # Schemas refer to each other as `#/components/schemas/...`: resolve them within the document.
    rooted = {**schema, "components": document["components"]}
    validator = jsonschema.Draft202012Validator(rooted, format_checker=jsonschema.FormatChecker())
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(instance)]


operations = [
    (method.upper(), path, operation)
    for path, item in document["paths"].items()
    for method, operation in item.items()
]

# Descriptions and examples of every operation.
created_schedule = None
for method, path, operation in operations:
    name = f"{method} {path}"
    if not operation.get("summary") or not operation.get("description"):
        fail(f"{name}: no summary or no description")
    for parameter in operation.get("parameters", []):
        if parameter["in"] in ("query", "header") and "example" not in parameter:
            fail(f"{name}: parameter {parameter['name']} has no example")
        if not parameter.get("description"):
            fail(f"{name}: parameter {parameter['name']} has no description")
    body = operation.get("requestBody")
    if body is None:
        continue
    media = body["content"].get("application/json", {})
    if "example" not in media:
        fail(f"{name}: the request body has no example")
        continue
    example = media["example"]
    for error in validate(example, media["schema"]):
        fail(f"{name}: the example breaks its schema: {error}")
    # The example as the docs UI's "try it" sends it.
    target = path
    if "{id}" in path:
        if created_schedule is None:
            fail(f"{name}: no schedule was created before it to try the example on")
            continue
        target = path.replace("{id}", created_schedule)
    status, text = call(method, target, example)
    if not 200 <= status < 300:
        fail(f"{name}: the example got {status}: {text[:300]}")
    elif operation.get("operationId") == "create_schedule":
        created_schedule = json.loads(text)["id"]
    print(f"{name}: example accepted ({status})")

# An example of every success response, in each content type, of the shape it documents.
response_examples = 0
for method, path, operation in operations:
    name = f"{method} {path}"
    for status, response in operation["responses"].items():
        if not status.startswith("2"):
            continue
        for media, content in response.get("content", {}).items():
            # Under `examples` (a named Example with its `value`): RapiDoc reads an `example`
            # object's members as Example objects and fails on a `null` one.
            answer = content.get("examples", {}).get("answer", {})
            if "value" not in answer:
                fail(f"{name} {status} {media}: no example")
                continue
            response_examples += 1
            example = answer["value"]
            if media == "application/json":
                for error in validate(example, content["schema"]):
                    fail(f"{name} {status}: the example breaks its schema: {error}")
            elif not isinstance(example, str) or not example:
                fail(f"{name} {status} {media}: the example is not text")
            elif media == "image/svg+xml":
                try:
                    ElementTree.fromstring(example)
                except ElementTree.ParseError as error:
                    fail(f"{name} {status}: the SVG example is not well-formed: {error}")
print(f"{response_examples} success examples checked")

# A description on every property of every schema, at any depth.
def walk(schema, where):
    if not isinstance(schema, dict):
        return
    for name, member in schema.get("properties", {}).items():
        if not isinstance(member, dict) or not member.get("description"):
            fail(f"{where}.{name}: no description")
        walk(member, f"{where}.{name}")
    for key in ("items", "additionalProperties"):
        walk(schema.get(key), f"{where}[]")
    for key in ("oneOf", "anyOf", "allOf"):
        for i, part in enumerate(schema.get(key, [])):
            walk(part, f"{where}.{key}[{i}]")


for name, schema in schemas.items():
    walk(schema, name)
properties = sum(
    1 for schema in schemas.values() for _ in json.dumps(schema).split('"properties"')[1:]
)

# Formats: times and ids.
for name, schema in schemas.items():
    if name == "ServerSentEvent":  # its `id` is the event stream's, not a resource's
        continue
    for prop, member in schema.get("properties", {}).items():
        if prop.endswith("_at") or prop == "scheduled_for":
            if member.get("format") != "date-time":
                fail(f"{name}.{prop}: a time without format date-time")
        if (prop in ("id", "job_id", "schedule_id")) and member.get("format") != "uuid":
            fail(f"{name}.{prop}: an id without format uuid")

# Headers on the answers that carry them.
for method, path, operation in operations:
    name = f"{method} {path}"
    for status, response in operation["responses"].items():
        headers = response.get("headers", {})
        wanted = {"201": "Location", "202": "Location", "429": "Retry-After", "503": "Retry-After"}
        if status in wanted and wanted[status] not in headers:
            fail(f"{name} {status}: {wanted[status]} undocumented")
    if operation.get("operationId") in ("get_result", "get_distribution", "get_life"):
        if "ETag" not in operation["responses"]["200"].get("headers", {}):
            fail(f"{name} 200: ETag undocumented")

# Content types.
def content_types(path, method="get", status="200"):
    return set(document["paths"][path][method]["responses"][status].get("content", {}))


expected = {
    "/v1/jobs/{id}/distributions/{metric}": {"application/json", "text/csv"},
    "/v1/jobs/{id}/life": {"application/json", "text/csv"},
    "/v1/jobs/{id}/plots/{kind}": {"image/svg+xml"},
    "/v1/schedules/{id}/plots/trend.svg": {"image/svg+xml"},
    "/v1/jobs/{id}/events": {"text/event-stream"},
    "/v1/events": {"text/event-stream"},
    "/metrics": {"text/plain"},
}
for path, types in expected.items():
    if content_types(path) != types:
        fail(f"GET {path} 200: documents {sorted(content_types(path))}, answers {sorted(types)}")

for failure in failures:
    print("FAIL", failure)
print(
    f"{len(operations)} operations, {len(schemas)} schemas: "
    f"{'all checks passed' if not failures else f'{len(failures)} failures'}"
)
sys.exit(1 if failures else 0)
