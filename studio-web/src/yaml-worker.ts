// The YAML worker of monaco-yaml, with one change: a schema named by a file's modeline
// ("# yaml-language-server: $schema=../schemas/mission.schema.json") resolves to a file: address, which a browser
// cannot fetch; any .../schemas/NAME.schema.json (or .../schemas/parts/NAME.schema.json) is read from the copy
// beside the page instead, wherever the file sits in the studio's folder.
import "./worker-fetch";
import "monaco-yaml/yaml.worker.js";
