// The studio page's libraries in one ES module, bundled by esbuild at build
// time (services/studio/CMakeLists.txt) into share/kinemo/studio-libs/ and
// served under /libs/: the page's main thread and its render worker import
// the same file (module workers cannot use an import map, and three's own
// modules import 'three' by its bare name).
export * from 'three';
export { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
export { DRACOLoader } from 'three/examples/jsm/loaders/DRACOLoader.js';
export { MeshoptDecoder } from 'three/examples/jsm/libs/meshopt_decoder.module.js';
export { MeshoptSimplifier } from 'three/examples/jsm/libs/meshopt_simplifier.module.js';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
export { BVHLoader } from 'three/examples/jsm/loaders/BVHLoader.js';
export { VRMLoaderPlugin, VRMUtils } from '@pixiv/three-vrm';
