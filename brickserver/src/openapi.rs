//! The OpenAPI 3.1 document served at `/openapi.json`, generated: its paths, methods and
//! parameters by `aide` from the routes and the types their handlers extract (each route
//! module documents its own responses, with the helpers here), and its component schemas by
//! `schemars` from the Rust types of the documents answered, exactly as the JSON Schema files
//! in `schemas/json/` are generated ([`residency_schemas::generate`]).

use aide::openapi::{
    Components, Info, MediaType, OpenApi, ReferenceOr, Response, SchemaObject, SecurityScheme,
    StatusCode,
};
use aide::transform::TransformOperation;
use residency_schemas::RegionMetadata;
use residency_schemas::generate::SchemaFile;
use residency_schemas::server::{ApiError, DatasetList, RegionAnswer};
use residency_schemas::wire::{BrickBatchHeader, MinMaxHierarchyHeader};
use schemars::{JsonSchema, Schema, json_schema};
use serde_json::Value;

/// The document's `info` and components, before the routes add their paths.
pub(crate) fn base() -> OpenApi {
    let mut components = Components::default();
    components.schemas.extend([
        component::<DatasetList>(),
        component::<RegionAnswer>(),
        component::<ApiError>(),
        component::<MinMaxHierarchyHeader>(),
        component::<BrickBatchHeader>(),
        component::<RegionMetadata>(),
    ]);
    components.security_schemes.insert(
        "bearer".into(),
        ReferenceOr::Item(SecurityScheme::Http {
            scheme: "bearer".into(),
            bearer_format: None,
            description: Some("Only when the server runs with --token-file.".into()),
            // No extensions (aide's map type is indexmap's).
            extensions: std::iter::empty().collect(),
        }),
    );
    OpenApi {
        info: Info {
            title: "Residency brickserver".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            description: Some(
                "Serves OME-Zarr stores verbatim at their Zarr keys (for any viewer), plus region \
                 metadata queries, the binary min/max hierarchy and batched bricks (for \
                 renderers), and the Residency web viewer. Read-only: GET, HEAD and OPTIONS \
                 only. With --token-file, every path but /healthz needs `Authorization: Bearer \
                 <token>`."
                    .into(),
            ),
            ..Info::default()
        },
        components: Some(components),
        ..OpenApi::default()
    }
}

/// The finished document as JSON: axum's wildcard captures (`{*key}`) written as OpenAPI
/// path parameters (`{key}`).
pub(crate) fn finish(mut api: OpenApi) -> Value {
    if let Some(paths) = &mut api.paths {
        paths.paths = std::mem::take(&mut paths.paths)
            .into_iter()
            .map(|(path, item)| (path.replace("{*", "{"), item))
            .collect();
    }
    serde_json::to_value(api).expect("an OpenAPI document always serializes")
}

/// The component schema of `T`, named as the type: the schema of its JSON Schema file, its
/// local references (`#/$defs/...`) re-rooted under `#/components/schemas/NAME/` and its
/// `$id` dropped, so OpenAPI tools that resolve every reference against the document root
/// find them.
fn component<T: JsonSchema>() -> (String, SchemaObject) {
    let name = T::schema_name().into_owned();
    let file = SchemaFile::written::<T>("");
    let mut value: Value =
        serde_json::from_str(&file.text).expect("a generated JSON Schema is JSON");
    reroot(&mut value, &format!("#/components/schemas/{name}"));
    let json_schema = Schema::try_from(value).expect("a generated JSON Schema is an object");
    (name, schema_object(json_schema))
}

/// `v` (a JSON Schema) with its local references (`#/...`) re-rooted under `prefix` and every
/// `$id` dropped.
fn reroot(v: &mut Value, prefix: &str) {
    match v {
        Value::Object(map) => {
            map.remove("$id");
            for (k, child) in map.iter_mut() {
                match child {
                    Value::String(r) if k == "$ref" && r.starts_with("#/") => {
                        *r = format!("{prefix}{}", &r[1..]);
                    }
                    _ => reroot(child, prefix),
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(|i| reroot(i, prefix)),
        _ => {}
    }
}

/// `json_schema` as OpenAPI schema object.
fn schema_object(json_schema: Schema) -> SchemaObject {
    SchemaObject {
        json_schema,
        example: None,
        external_docs: None,
    }
}

/// A response without content.
pub(crate) fn answer(description: &str) -> Response {
    Response {
        description: description.into(),
        ..Response::default()
    }
}

/// `response` with a body of media type `media` described by `schema`.
pub(crate) fn with_content(mut response: Response, media: &str, schema: Schema) -> Response {
    response.content.insert(
        media.into(),
        MediaType {
            schema: Some(schema_object(schema)),
            ..MediaType::default()
        },
    );
    response
}

/// The schema of a text body.
pub(crate) fn string() -> Schema {
    json_schema!({"type": "string"})
}

/// The schema of a binary body of media type `media`.
pub(crate) fn binary(media: &str) -> Schema {
    json_schema!({"type": "string", "contentMediaType": media})
}

/// A reference to the component schema of `T`.
pub(crate) fn component_ref<T: JsonSchema>() -> Schema {
    json_schema!({"$ref": format!("#/components/schemas/{}", T::schema_name())})
}

/// A plain-text answer.
pub(crate) fn text(description: &str) -> Response {
    with_content(answer(description), "text/plain", string())
}

/// An HTML page.
pub(crate) fn page(description: &str) -> Response {
    with_content(answer(description), "text/html", string())
}

/// A JSON answer of the document type `T`.
pub(crate) fn json<T: JsonSchema>(description: &str) -> Response {
    with_content(
        answer(description),
        "application/json",
        component_ref::<T>(),
    )
}

/// Documents `answers` (status code, response) as responses of the operation.
pub(crate) fn responses(
    mut op: TransformOperation<'_>,
    answers: impl IntoIterator<Item = (u16, Response)>,
) -> TransformOperation<'_> {
    let documented = op.inner_mut().responses.get_or_insert_default();
    for (status, response) in answers {
        documented
            .responses
            .insert(StatusCode::Code(status), ReferenceOr::Item(response));
    }
    op
}

/// Documents the JSON error answers ([`ApiError`]) of an API operation: status code and when.
pub(crate) fn api_errors<'a>(
    op: TransformOperation<'a>,
    errors: &[(u16, &str)],
) -> TransformOperation<'a> {
    let answers = errors.iter().map(|&(s, why)| (s, json::<ApiError>(why)));
    responses(op, answers)
}

#[cfg(test)]
mod tests {
    use residency_schemas::generate::schema_dir;
    use serde_json::Value;

    use super::{base, reroot};

    /// The component schemas are the committed JSON Schema files, re-rooted, under the names
    /// the OpenAPI clients know.
    #[test]
    fn components_are_the_schema_files() {
        let api = base();
        let schemas = &api.components.as_ref().expect("components").schemas;
        let files = [
            ("DatasetList", "datasets.schema.json"),
            ("RegionAnswer", "region-answer.schema.json"),
            ("ApiError", "api-error.schema.json"),
            ("MinMaxHierarchyHeader", "minmax-hierarchy.schema.json"),
            ("BrickBatchHeader", "brick-batch.schema.json"),
            ("RegionMetadata", "region-metadata.schema.json"),
        ];
        assert_eq!(schemas.len(), files.len());
        for (name, file) in files {
            let text = std::fs::read_to_string(schema_dir().join(file)).expect(file);
            let mut value: Value = serde_json::from_str(&text).expect(file);
            reroot(&mut value, &format!("#/components/schemas/{name}"));
            assert_eq!(schemas[name].json_schema.as_value(), &value, "{name}");
        }
    }
}
