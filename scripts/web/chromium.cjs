// The options the scripts in scripts/web start headless Chromium with:
// software WebGL (SwiftShader), nothing fetched from the network.
const kChromiumFlags = ['--no-sandbox', '--disable-gpu-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
                        '--disable-background-networking', '--disable-component-update', '--disable-sync',
                        '--no-first-run'];

module.exports = { kChromiumFlags };
