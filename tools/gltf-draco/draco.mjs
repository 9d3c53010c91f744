// Compresses every mesh of a glTF file with Draco (KHR_draco_mesh_compression,
// required), through glTF Transform and Google's encoder (draco3dgltf):
//
//   node draco.mjs IN.glb OUT.glb [edgebreaker|sequential]
//
// Positions are quantized to 14 bits and normals to 10 over each mesh's
// bounds (glTF Transform's defaults).
import { NodeIO } from "@gltf-transform/core";
import { ALL_EXTENSIONS, KHRDracoMeshCompression } from "@gltf-transform/extensions";
import draco3d from "draco3dgltf";

const [input, output, method = "edgebreaker"] = process.argv.slice(2);
if (!input || !output || !["edgebreaker", "sequential"].includes(method)) {
  console.error("usage: node draco.mjs IN.glb OUT.glb [edgebreaker|sequential]");
  process.exit(2);
}
const io = new NodeIO().registerExtensions(ALL_EXTENSIONS).registerDependencies({
  "draco3d.encoder": await draco3d.createEncoderModule(),
  "draco3d.decoder": await draco3d.createDecoderModule(),
});
const doc = await io.read(input);
const { EncoderMethod } = KHRDracoMeshCompression;
doc.createExtension(KHRDracoMeshCompression).setRequired(true).setEncoderOptions({
  method: method === "sequential" ? EncoderMethod.SEQUENTIAL : EncoderMethod.EDGEBREAKER,
});
await io.write(output, doc);
